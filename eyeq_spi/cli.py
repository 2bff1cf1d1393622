"""Command-line interface. Every ``EyeqError`` becomes a one-line message and exit code 2; a
user never sees a traceback for bad input."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from eyeq_spi import __version__
from eyeq_spi.errors import EyeqError, UsageError


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(message)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="eyeq-spi", description=__doc__)
    p.add_argument("--version", action="version", version=f"eyeq-spi {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    from eyeq_spi.cli_run import add_shared_options

    demo = sub.add_parser(
        "demo",
        help="host emulator against the embedded simulated EyeQ",
        description="Bring a simulated EyeQ4 up to Running Vision with the host emulator, in "
        "one process, over the real link and transport. Exit 0 only if Running Vision was "
        "reached and held.",
    )
    demo.add_argument("--duration", type=float, default=10.0, help="seconds (default 10)")
    demo.add_argument("--virtual-time", action="store_true",
                      help="run as fast as the CPU allows instead of in real time")
    demo.add_argument("--json", action="store_true", help="end with one JSON object")
    add_shared_options(demo)
    sim = sub.add_parser("sim", help="the simulated EyeQ on a TCP listener or a pty")
    sim.add_argument("--listen", metavar="tcp://HOST:PORT", help="serve a socket:// URL")
    sim.add_argument("--pty", action="store_true", help="open a pty and print its path")
    sim.add_argument("--duration", type=float, help="stop after S seconds (default: never)")
    sim.add_argument("--accept-timeout", type=float, default=60.0, help="wait for the host")
    sim.add_argument("--json", action="store_true", help="end with one JSON object")
    add_shared_options(sim)
    host = sub.add_parser("host", help="the host emulator against an EyeQ at a pyserial URL")
    host.add_argument("--port", required=True, metavar="URL",
                      help="socket://HOST:PORT, a tty or pty path, rfc2217://..., loop://")
    host.add_argument("--nvm", metavar="FILE", help="NVM file (default: in memory)")
    host.add_argument("--duration", type=float, default=10.0, help="seconds (default 10)")
    host.add_argument("--exit-when-running", action="store_true",
                      help="stop as soon as Running Vision is reached")
    host.add_argument("--json", action="store_true", help="end with one JSON object")
    add_shared_options(host)
    from eyeq_spi.cli_dissect import add_dissect_parser

    add_dissect_parser(sub)
    spec = sub.add_parser("spec", help="browse the message catalogue built from specs/")
    spec_sub = spec.add_subparsers(dest="spec_command", required=True, parser_class=_Parser)
    sl = spec_sub.add_parser("list", help="list messages, MESP functions, init messages, structs")
    sl.add_argument("--sw", help="SW version for sizes (default: newest)")
    ss = spec_sub.add_parser("show", help="offsets, sizes, types and CRC coverage of one entry")
    ss.add_argument("name", help="message, struct, init message, MESP function or enum name")
    ss.add_argument("--sw", help="SW version, e.g. 9.0, 8.1 or sw5 (default: newest)")
    return p


def _spec(args: argparse.Namespace) -> int:
    from eyeq_spi.codec.describe import spec_list, spec_show
    from eyeq_spi.spec.catalog import catalog

    cat = catalog()
    sw = cat.sw(args.sw)
    text = spec_list(cat, sw) if args.spec_command == "list" else spec_show(cat, args.name, sw)
    print(text)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        if args.command in ("demo", "sim", "host"):
            from eyeq_spi import cli_run

            run = {"demo": cli_run.run_demo, "sim": cli_run.run_sim, "host": cli_run.run_host}
            return run[args.command](args)
        if args.command == "spec":
            return _spec(args)
        if args.command in ("dissect", "wireshark"):
            from eyeq_spi import cli_dissect

            return (cli_dissect.run_dissect if args.command == "dissect"
                    else cli_dissect.run_wireshark)(args)
        raise UsageError(f"unknown command {args.command}")
    except UsageError as exc:
        print(f"eyeq-spi: usage error: {exc}", file=sys.stderr)
        return 2
    except EyeqError as exc:
        print(f"eyeq-spi: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # output piped into head & co.
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as exc:
        print(f"eyeq-spi: internal error: {type(exc).__name__}: {exc} (please report this)",
              file=sys.stderr)
        return 3


if __name__ == "__main__":
    sys.exit(main())
