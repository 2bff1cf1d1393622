"""Command-line interface. Every ``EyeqError`` becomes a one-line message and exit code 2; a
user never sees a traceback for bad input."""

from __future__ import annotations

import argparse
import json
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
    demo = sub.add_parser(
        "demo",
        help="host stack against the embedded simulated EyeQ, in virtual time",
        description="Run the host and EyeQ protocol stacks against each other over an in-memory "
        "SPI link. (Until the host emulator lands this exercises link and transport: both sides "
        "exchange messages of random sizes up to each side's receive limit.)",
    )
    demo.add_argument("--duration", type=float, default=10.0, help="virtual seconds (default 10)")
    demo.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    demo.add_argument("--rate", type=float, default=50.0, help="messages/s each way (default 50)")
    demo.add_argument("--json", action="store_true", help="print one JSON object at the end")
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
        if args.command == "demo":
            from eyeq_spi.demo import run_link_demo

            if args.duration <= 0 or args.rate <= 0:
                raise UsageError("--duration and --rate must be positive")
            result = run_link_demo(args.duration, seed=args.seed, rate=args.rate)
            if args.json:
                print(json.dumps(result, sort_keys=True))
            else:
                for side in ("host", "eyeq"):
                    r = result[side]
                    print(f"{side:5s} sent {r['sent']:6d}  received {r['received']:6d}  "
                          f"failed {r['failed']:4d}  intact {r['intact']}")
                print(f"virtual time {result['virtual_s']:.3f} s, wall {result['wall_s']:.3f} s")
            return 0 if result["ok"] else 1
        if args.command == "spec":
            return _spec(args)
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


if __name__ == "__main__":
    sys.exit(main())
