"""Command-line interface. Every ``EyeqError`` becomes a one-line message and exit code 2; a
user never sees a traceback for bad input. What ``--help`` shows is in :mod:`eyeq_spi.cli.help`."""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Callable, Sequence
from typing import Any

from eyeq_spi import __version__
from eyeq_spi.errors import EyeqError, UsageError


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(message)


# Every subcommand with its one-line help, in --help order. main() builds the options of the
# command it runs only; the others are a name and this line, which is all --help and a usage error
# show. tests/test_startup.py holds the table to the full parser.
COMMANDS: dict[str, str] = {
    "demo": "host emulator against the embedded simulated EyeQ",
    "sim": "the simulated EyeQ on a TCP listener or a pty",
    "host": "the host emulator against an EyeQ at --port URL",
    "dissect": "decode SPI captures (pcapng, raw, hex, Saleae, VCD)",
    "wireshark": "generate the Wireshark Lua dissector from specs/",
    "batch": "many captures into one partitioned Parquet dataset",
    "can": "Mobileye CAN: DBCs, decode logs or a live bus, compare",
    "plot": "bird's-eye scene, stream timing or link behaviour of a capture",
    "monitor": "live terminal view of demo, host or a replayed capture",
    "export": "a capture as VCD waveforms, MDF4 or MCAP",
    "replay": "play a capture's EyeQ channel to a host",
    "sigrok-decoder": "install the eyeq_spi decoder for sigrok/PulseView",
    "conformance": "protocol conformance suite: verdict per requirement",
    "spec": "browse the message catalogue built from specs/",
}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The whole parser; with ``only``, the options of that command alone (every other command
    is its name and help line from :data:`COMMANDS`, enough for ``--help`` and usage errors)."""
    p = _Parser(prog="eyeq-spi")
    p.add_argument("--version", action="version", version=f"eyeq-spi {__version__}")
    p.add_argument("--print-completion", choices=("bash", "zsh", "tcsh"), metavar="SHELL",
                   help="print the shell completion script for SHELL (bash, zsh, tcsh; "
                   "docs/cli.md says where to put it)")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser,
                           title="commands", metavar="COMMAND")
    for names, add in _groups():
        if only is None or only in names or not all(n in COMMANDS for n in names):
            add(sub)
        else:
            for n in names:
                sub.add_parser(n, help=COMMANDS[n])
    return p


def _groups() -> list[tuple[tuple[str, ...], Callable[[Any], None]]]:
    """Each function adding subcommands, with the names it adds, in --help order."""
    return [
        (("demo", "sim", "host"), _add_run), (("dissect", "wireshark"), _add_dissect),
        (("batch",), _add_batch), (("can",), _add_can), (("plot", "monitor"), _add_plot),
        (("export", "replay", "sigrok-decoder"), _add_bench),
        (("conformance",), _add_conformance), (("spec",), _add_spec),
    ]


def _command(argv: Sequence[str]) -> str:
    """The subcommand ``argv`` names, "" if none (``--print-completion`` takes a value)."""
    rest = [a for k, a in enumerate(argv)
            if k == 0 or argv[k - 1] != "--print-completion"]
    return next((a for a in rest if not a.startswith("-")), "")


def _parser_for(argv: Sequence[str]) -> argparse.ArgumentParser:
    """The parser ``main`` needs: one command's options; with help asked for (or nothing
    given), descriptions and examples too; for a completion script, every command's."""
    p = build_parser(only=None if "--print-completion" in argv else _command(argv))
    if not argv or "-h" in argv or "--help" in argv:
        from eyeq_spi.cli.help import finish

        finish(p)
    return p


def _completion(parser: argparse.ArgumentParser, shell: str) -> int:
    try:
        import shtab
    except ImportError:
        raise UsageError("shell completion needs shtab: pip install shtab") from None
    sys.stdout.write(shtab.complete(parser, shell=shell))
    return 0


def _add_run(sub: Any) -> None:
    from eyeq_spi.cli import args as ca
    from eyeq_spi.cli.run import add_shared_options

    seconds = ca.number(0, 86_400, lo_open=True, unit="s")

    demo = sub.add_parser(
        "demo",
        help="host emulator against the embedded simulated EyeQ",
        description="Bring a simulated EyeQ4 up to Running Vision with the host emulator, in "
        "one process, over the real link and transport. Exit 0 only if Running Vision was "
        "reached and held.",
    )
    demo.add_argument("--duration", type=seconds, default=10.0,
                      help="seconds, (0, 86400] (default 10)")
    demo.add_argument("--virtual-time", action="store_true",
                      help="run as fast as the CPU allows instead of in real time")
    demo.add_argument("--nvm", metavar="FILE", type=ca.output_file,
                      help="the host's NVM as a JSON file, read at the start and written "
                      "atomically: the next run starts with the calibration it learned "
                      "(default: in memory, empty)")
    demo.add_argument("--json", action="store_true", help="end with one JSON object")
    add_shared_options(demo, side="demo")
    sim = sub.add_parser(
        "sim", help="the simulated EyeQ on a TCP listener or a pty",
        description="The simulated EyeQ in real time. It prints LISTEN URL (or PTY PATH) on "
        "stderr as soon as it waits for a host: hand exactly that URL to eyeq-spi host --port. "
        "It serves one host after another (each connection is a power-up) and ends with one "
        "summary: per host served and in total.")
    ep = sim.add_mutually_exclusive_group(required=True)
    ep.add_argument("--listen", dest="endpoint", action=ca.Endpoint, metavar="tcp://HOST:PORT",
                    help="listen here for the host (port 0: any free port)")
    ep.add_argument("--pty", dest="endpoint", nargs=0, action=ca.Endpoint,
                    help="open a pty and print its path; the host opens it as a serial port")
    ep.add_argument("--port", dest="endpoint", action=ca.Endpoint, port_listens=True,
                    help=argparse.SUPPRESS)  # old spelling of --listen / --pty
    sim.set_defaults(listen=None, pty=False, port=None)
    sim.add_argument("--duration", type=seconds, help="stop after S seconds (default: never)")
    sim.add_argument("--accept-timeout", type=seconds, default=60.0,
                     help="seconds to wait for the host, (0, 86400] (default 60)")
    sim.add_argument("--json", action="store_true", help="end with one JSON object")
    sim.add_argument("--rt-priority", type=ca.integer(0, 99), default=10, metavar="N",
                     help="SCHED_FIFO priority 1..99 so that ACKs meet the 10 ms ackTimeout on a "
                     "busy machine; 0: ordinary scheduling (default 10; falls back when refused)")
    add_shared_options(sim, side="sim")
    host = sub.add_parser("host", help="the host emulator against an EyeQ at --port URL")
    host.add_argument("--port", required=True, metavar="URL", type=ca.connect_address,
                      help="the EyeQ: tcp://HOST:PORT as eyeq-spi sim prints it (socket:// "
                      "too), rfc2217://HOST:PORT, or a tty or pty path")
    host.add_argument("--nvm", metavar="FILE", type=ca.output_file,
                      help="NVM file, JSON, written atomically (default: in memory)")
    host.add_argument("--duration", type=seconds, default=10.0,
                      help="seconds, (0, 86400] (default 10)")
    host.add_argument("--exit-when-running", action="store_true",
                      help="stop as soon as Running Vision is reached")
    host.add_argument("--reconnect", action="store_true",
                      help="wait for the EyeQ at the start and whenever the link is lost, "
                           "and run the bring-up again")
    host.add_argument("--json", action="store_true", help="end with one JSON object")
    host.add_argument("--rt-priority", type=ca.integer(0, 99), default=10, metavar="N",
                      help="SCHED_FIFO priority 1..99 so that ACKs meet the 10 ms ackTimeout on "
                      "a busy machine; 0: ordinary scheduling (default 10; falls back when "
                      "refused)")
    add_shared_options(host, side="host")


def _add_dissect(sub: Any) -> None:
    from eyeq_spi.cli.dissect import add_dissect_parser

    add_dissect_parser(sub)


def _add_batch(sub: Any) -> None:
    from eyeq_spi.cli.batch import add_batch_parser

    add_batch_parser(sub)


def _add_can(sub: Any) -> None:
    from eyeq_spi.cli.can import add_can_parser

    add_can_parser(sub)


def _add_plot(sub: Any) -> None:
    from eyeq_spi.cli.plot import add_plot_parser

    add_plot_parser(sub)


def _add_bench(sub: Any) -> None:
    from eyeq_spi.cli.export import add_bench_parser

    add_bench_parser(sub)


def _add_conformance(sub: Any) -> None:
    from eyeq_spi.cli.conformance import add_conformance_parser

    add_conformance_parser(sub)


def _add_spec(sub: Any) -> None:
    from eyeq_spi.cli import args as ca

    spec = sub.add_parser("spec", help="browse the message catalogue built from specs/")
    spec_sub = spec.add_subparsers(dest="spec_command", required=True, parser_class=_Parser)
    sl = spec_sub.add_parser("list", help="list messages, MESP functions, init messages, structs")
    sl.add_argument("--sw", type=ca.sw_release, help="SW release for sizes (default: newest)")
    ss = spec_sub.add_parser("show", help="offsets, sizes, types and CRC coverage of one entry")
    ss.add_argument("name", help="message, struct, init message, MESP function or enum: name "
                    "(any case, or part of one) or data ID such as 0xE4")
    ss.add_argument("--sw", type=ca.sw_release,
                    help="SW release, e.g. 9.0, 8.1 or sw5 (default: newest)")


def _spec(args: argparse.Namespace) -> int:
    from eyeq_spi.codec.describe import spec_list, spec_show
    from eyeq_spi.spec.catalog import catalog

    cat = catalog()
    sw = cat.sw(args.sw)
    if args.spec_command == "list":
        text = spec_list(cat, sw)
    else:
        from eyeq_spi.cli.args import spec_entry

        try:
            name = spec_entry(args.name)
        except argparse.ArgumentTypeError as exc:
            raise UsageError(f"argument NAME: {exc}") from None
        text = spec_show(cat, name, sw)
    print(text)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        parser = _parser_for(argv)
        if not argv:  # bare eyeq-spi: what it is, the commands, examples
            sys.stdout.write(parser.format_help())
            return 0
        if "--print-completion" in argv and _command(argv) == "":
            k = argv.index("--print-completion") + 1
            shell = argv[k] if k < len(argv) else ""
            if shell not in ("bash", "zsh", "tcsh"):
                raise UsageError(f"argument --print-completion: give bash, zsh or tcsh, "
                                 f"not {shell!r}")
            return _completion(parser, shell)
        args = parser.parse_args(argv)
        if args.command in ("demo", "sim", "host"):
            from eyeq_spi.cli import run as cli_run

            run = {"demo": cli_run.run_demo, "sim": cli_run.run_sim, "host": cli_run.run_host}
            return run[args.command](args)
        if args.command == "spec":
            return _spec(args)
        if args.command in ("plot", "monitor"):
            from eyeq_spi.cli import plot as cli_plot

            return (cli_plot.run_plot if args.command == "plot" else cli_plot.run_monitor)(args)
        if args.command == "can":
            from eyeq_spi.cli import can as cli_can

            return cli_can.run_can(args)
        if args.command in ("export", "replay", "sigrok-decoder"):
            from eyeq_spi.cli import export as cli_bench

            return {"export": cli_bench.run_export, "replay": cli_bench.run_replay,
                    "sigrok-decoder": cli_bench.run_sigrok_decoder}[args.command](args)
        if args.command == "conformance":
            from eyeq_spi.cli import conformance as cli_conformance

            return cli_conformance.run_conformance(args)
        if args.command == "batch":
            from eyeq_spi.cli import batch as cli_batch

            return cli_batch.run_batch(args)
        if args.command in ("dissect", "wireshark"):
            from eyeq_spi.cli import dissect as cli_dissect

            return (cli_dissect.run_dissect if args.command == "dissect"
                    else cli_dissect.run_wireshark)(args)
        raise UsageError(f"unknown command {args.command}")
    except UsageError as exc:
        return _fail(f"usage error: {exc}")
    except EyeqError as exc:
        return _fail(f"error: {exc}")
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # output piped into head & co.: stop quietly
        return _quiet_pipe()
    except OSError as exc:  # a file or device the user named (disk full, vanished, ...)
        where = f" {exc.filename}" if exc.filename else ""
        return _fail(f"error:{where}: {exc.strerror or exc}")
    except Exception as exc:
        return _fail(f"internal error: {type(exc).__name__}: {exc} (please report this)", 3)


def _fail(message: str, code: int = 2) -> int:
    """One line on stderr, whatever the message holds."""
    from eyeq_spi.cli.args import one_line

    with contextlib.suppress(OSError):  # stderr is gone too
        print(f"eyeq-spi: {one_line(message)}", file=sys.stderr, flush=True)
    return code


def _quiet_pipe() -> int:
    """The reader of stdout went away: point stdout at /dev/null so the interpreter's final
    flush does not print a second error, and exit 0 as head(1)'s writers do."""
    import os

    with contextlib.suppress(OSError, ValueError):
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


if __name__ == "__main__":
    sys.exit(main())
