"""``eyeq-spi export``: a capture as sigrok session or VCD waveforms, MDF4 or MCAP."""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

from eyeq_spi.cli import inputs
from eyeq_spi.errors import UsageError


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import args as ca
    from eyeq_spi.cli import options as opt

    parser = sub.add_parser(name, help=help, parents=[opt.capture_input()],
                       description="Turn a capture into SPI waveforms for PulseView (--sr, "
                       "a compressed sigrok session file; --vcd for other waveform tools), "
                       "decoded signals for asammdf/CANape (--mdf) or raw transfers and decoded "
                       "messages for Foxglove (--mcap). Several outputs may be given at once.")
    inputs.add_capture_argument(parser)
    parser.add_argument("--sr", metavar="OUT.sr", type=ca.output_file,
                   help="SPI waveforms as a sigrok session file (PulseView opens it, sigrok-cli "
                   "-i reads it): 20 MHz samples, deflate-compressed, the suggested form")
    parser.add_argument("--sr-max-idle", type=ca.number(0, 3600, lo_open=True, unit="s"),
                   metavar="S", help="--sr: shorten every stretch with both channels idle to "
                   "at most S seconds (idle time costs about 0.1 s of export time per second); "
                   "default: capture timing")
    parser.add_argument("--vcd", metavar="OUT.vcd", type=ca.output_file,
                   help="SPI waveforms, 10 MHz, mode 1 (about 30 bytes per bit sent: the size "
                   "is said before writing)")
    parser.add_argument("--vcd-max-idle", type=ca.number(0, 3600, lo_open=True, unit="s"),
                   metavar="S", help="--vcd: shorten every stretch with both channels idle to "
                   "at most S seconds (smaller timestamps, and sigrok samples no idle time); "
                   "default: capture timing")
    parser.add_argument("--vcd-max-size", type=ca.number(0, 1e6, lo_open=True, unit="MB"),
                   default=2000.0, metavar="MB", help="--vcd: refuse, before writing, a VCD "
                   "estimated larger than this (default 2000 MB)")
    parser.add_argument("--mdf", metavar="OUT.mf4", type=ca.output_file,
                   help="decoded signals (needs the [export] extra)")
    parser.add_argument("--mcap", metavar="OUT.mcap", type=ca.output_file,
                   help="raw transfers and decoded messages (needs the [export] extra), and "
                   "with the [foxglove] extra the 3D scene, plots and log for Foxglove, with "
                   "its layout in OUT.layout.json beside it")
    opt.include(parser, opt.json_out("end with one JSON summary object"))


def run(args: argparse.Namespace) -> int:
    from eyeq_spi.cli.options import spi_options
    from eyeq_spi.cli.progress import JobProgress
    from eyeq_spi.interop.export import export, export_mdf

    if not (args.sr or args.vcd or args.mdf or args.mcap):
        raise UsageError("give at least one of --sr, --vcd, --mdf, --mcap")
    # else MDF alone, from the pipeline's records
    transfers = bool(args.sr or args.vcd or args.mcap)
    total = _vcd_plan(args) if args.capture != "-" and transfers else None
    cap = inputs.open_input(args, "export")
    try:
        if transfers:
            with JobProgress(f"export {os.path.basename(args.capture)}", total,
                             unit="transfers", enabled=None if total else False) as bar:
                summary = export(cap.transfers, source=args.capture, sw=cap.release.key,
                                 vcd=args.vcd, mdf=args.mdf, mcap=args.mcap, sr=args.sr,
                                 sr_max_idle=args.sr_max_idle,
                                 spi=spi_options(args),
                                 vcd_max_idle=args.vcd_max_idle, progress=bar.update,
                                 mcap_extra=_foxglove_scene(args.mcap))
        else:
            with JobProgress(f"export {os.path.basename(args.capture)}",
                             enabled=None if args.capture != "-" else False) as bar:
                cap.progress = lambda _path, done, size: bar.update(done, size)
                summary = export_mdf(cap.items, args.mdf, source=args.capture,
                                     sw=cap.release.key)
    finally:
        cap.close()
    if args.json:
        print(json.dumps(summary, separators=(",", ":")))
    else:
        for line in summary["written"]:
            print(f"wrote {line}")
    return inputs.tail_note("export", args.capture, cap.tail)


def _foxglove_scene(mcap: str | None) -> Any:
    """``--mcap``: the Foxglove scene's topics and layout, when the [foxglove] extra is there
    (without it the MCAP holds today's topics, and stderr says what the extra would add)."""
    if not mcap:
        return None
    import importlib.util

    if importlib.util.find_spec("mcap") is None:
        return None  # no MCAP at all: the export says which extra that needs
    if importlib.util.find_spec("foxglove") is None:
        print("eyeq-spi export: no 3D scene in the MCAP: pip install 'eyeq-spi[foxglove]' adds "
              "it (and a Foxglove layout)", file=sys.stderr)
        return None
    from eyeq_spi.foxglove.mcap_sink import McapScene, layout_path

    return lambda writer, codec: McapScene(writer, codec, layout_path(mcap))


def _vcd_plan(args: argparse.Namespace) -> int:
    """A first pass over the capture: how many transfers it holds (the progress bar's total)
    and, for --vcd, the VCD's estimated size, said on stderr before anything is written and
    refused above --vcd-max-size."""
    from eyeq_spi.logic.vcd_write import estimate_size

    cap = inputs.open_input(args, "export", quiet=True)
    count = nbytes = 0
    t0 = t1 = None
    try:
        for rec in cap.transfers:
            count += 1
            nbytes += len(rec.data)
            if rec.time is not None:
                t0 = rec.time if t0 is None else t0
                t1 = rec.time
    finally:
        cap.close()
    if args.vcd:
        span = (t1 - t0) if t0 is not None and t1 is not None else count * 5e-4
        if args.vcd_max_idle is not None:
            span = min(span, count * (args.vcd_max_idle + 15e-6))
        size = estimate_size(count, nbytes, span)
        mb = size / 1e6
        capture = os.path.getsize(args.capture) / 1e6
        if mb > args.vcd_max_size:
            raise UsageError(f"the VCD of {args.capture} would be about {mb:,.0f} MB "
                             f"({count:,} transfers, {nbytes * 8:,} bits; a VCD holds every clock "
                             f"edge); raise --vcd-max-size or export part of the capture")
        print(f"eyeq-spi: {os.path.basename(args.vcd)} will be about {mb:,.0f} MB "
              f"({capture:,.1f} MB capture; a VCD holds every clock edge)", file=sys.stderr)
    return count
