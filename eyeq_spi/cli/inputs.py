"""The capture input of the commands that read one capture (export, replay, plot, monitor
--replay): its options and argument, opening it with its release, and the exit code of a capture
cut inside a block."""

from __future__ import annotations

import argparse
import sys
from typing import Any


def add_capture_argument(parser: Any) -> None:
    parser.add_argument("capture", metavar="CAPTURE",
                   help="a capture in any format dissect reads (pcapng, raw, hex, Saleae, VCD)")


def open_input(args: argparse.Namespace, command: str, path: str | None = None, *,
               quiet: bool = False, pace_gc: bool = True) -> Any:
    """The capture (``path``, default ``args.capture``) opened by the dissect pipeline with its
    release (one warning line when ``--sw`` disagrees, unless ``quiet``); the caller closes
    it."""
    from eyeq_spi.cli.options import spi_options
    from eyeq_spi.dissect.pipeline import DissectConfig, open_capture_file

    cf = open_capture_file(path or args.capture, DissectConfig(
        fmt=args.format, direction=getattr(args, "direction", None), spi=spi_options(args),
        sw=args.sw, pace_gc=pace_gc))
    if cf.release.warning and not quiet:
        print(f"eyeq-spi {command}: warning: {cf.release.warning}", file=sys.stderr,
              flush=True)
    return cf


def tail_note(command: str, path: str, tail: Any) -> int:
    """Exit 1 with one line when the reader left an incomplete last block, else 0."""
    if tail is None or not tail.ignored:
        return 0
    print(f"eyeq-spi {command}: {tail.note(path)}", file=sys.stderr, flush=True)
    return 1
