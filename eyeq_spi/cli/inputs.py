"""The capture input of the commands that read one capture (export, replay, plot, monitor
--replay): its options and argument, opening it with its release, and the exit code of a capture
cut inside a block."""

from __future__ import annotations

import argparse
import sys
from typing import IO, Any


def capture_parents() -> list[Any]:
    """The capture-input options of export and replay."""
    from eyeq_spi.cli import options as opt

    return [opt.capture_input(direction_help="channel of an input without directions")]


def add_capture_argument(p: Any) -> None:
    p.add_argument("capture", metavar="CAPTURE",
                   help="a capture in any format dissect reads (pcapng, raw, hex, Saleae, VCD)")


def open_input(args: argparse.Namespace, command: str, *,
               quiet: bool = False) -> tuple[IO[bytes], Any]:
    """The capture opened with its release (``--sw`` overrides, one warning line when they
    disagree, unless ``quiet``: a first pass that only counts) and its tail (a pcapng cut
    inside a block is read up to its last whole block)."""
    from eyeq_spi.cli.options import spi_options
    from eyeq_spi.dissect.inputs import InputError
    from eyeq_spi.dissect.release import open_capture

    if args.capture == "-":
        fh: IO[bytes] = sys.stdin.buffer
    else:
        try:
            fh = open(args.capture, "rb")  # noqa: SIM115 - closed by the caller
        except OSError as exc:
            raise InputError(f"{args.capture}: {exc.strerror or exc}") from None
    try:
        cap = open_capture(fh, args.format, args.direction, spi_options(args), sw=args.sw,
                           name=args.capture)
    except BaseException:
        if fh is not sys.stdin.buffer:
            fh.close()
        raise
    if cap.release.warning and not quiet:
        print(f"eyeq-spi {command}: warning: {cap.release.warning}", file=sys.stderr,
              flush=True)
    return fh, cap


def release(path: str, sw: str | None, fmt: str | None, direction: str | None,
             command: str) -> str:
    """The release a capture is read with (the capture's own unless ``--sw``), with the
    one-line warning when they disagree."""
    from eyeq_spi.dissect.release import release_of

    rel = release_of(path, sw, fmt, direction)
    if rel.warning:
        print(f"eyeq-spi {command}: warning: {rel.warning}", file=sys.stderr, flush=True)
    return rel.key


def tail_note(command: str, path: str, tail: Any) -> int:
    """Exit 1 with one line when the reader left an incomplete last block, else 0."""
    if tail is None or not tail.ignored:
        return 0
    print(f"eyeq-spi {command}: {tail.note(path)}", file=sys.stderr, flush=True)
    return 1
