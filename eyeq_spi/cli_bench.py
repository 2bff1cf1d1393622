"""``eyeq-spi export``, ``eyeq-spi replay`` and ``eyeq-spi sigrok-decoder``."""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

from eyeq_spi.errors import UsageError

_FORMATS = ("raw", "hex", "pcapng", "saleae2", "saleae1", "vcd")


def _input_options(p: Any) -> None:
    from eyeq_spi.logic.options import add_spi_arguments

    p.add_argument("capture", metavar="CAPTURE",
                   help="a capture in any format dissect reads (pcapng, raw, hex, Saleae, VCD)")
    p.add_argument("--format", choices=_FORMATS, help="skip detection")
    p.add_argument("--direction", choices=("h2e", "e2h"),
                   help="channel of an input without directions")
    p.add_argument("--sw", help="SW release of the traffic (default: the one the capture "
                   "records or shows, else the newest)")
    add_spi_arguments(p)


def add_bench_parser(sub: Any) -> None:
    from eyeq_spi import cli_args as ca

    e = sub.add_parser("export", help="a capture as VCD waveforms, MDF4 or MCAP",
                       description="Turn a capture into SPI waveforms for PulseView (--vcd), "
                       "decoded signals for asammdf/CANape (--mdf) or raw transfers and decoded "
                       "messages for Foxglove (--mcap). Several outputs may be given at once.")
    _input_options(e)
    e.add_argument("--vcd", metavar="OUT.vcd", type=ca.output_file,
                   help="SPI waveforms, 10 MHz, mode 1 (about 30 bytes per bit sent: the size "
                   "is said before writing)")
    e.add_argument("--vcd-max-idle", type=ca.number(0, 3600, lo_open=True, unit="s"),
                   metavar="S", help="--vcd: shorten every stretch with both channels idle to "
                   "at most S seconds (smaller timestamps, and sigrok samples no idle time); "
                   "default: capture timing")
    e.add_argument("--vcd-max-size", type=ca.number(0, 1e6, lo_open=True, unit="MB"),
                   default=2000.0, metavar="MB", help="--vcd: refuse, before writing, a VCD "
                   "estimated larger than this (default 2000 MB)")
    e.add_argument("--mdf", metavar="OUT.mf4", type=ca.output_file,
                   help="decoded signals (needs the [bench] extra)")
    e.add_argument("--mcap", metavar="OUT.mcap", type=ca.output_file,
                   help="raw transfers and decoded messages (needs the [bench] extra)")
    e.add_argument("--json", action="store_true", help="end with one JSON summary object")
    r = sub.add_parser("replay", help="play a capture's EyeQ channel to a host",
                       description="Play the EyeQ channel (e2h) of a capture to a host under "
                       "test in real time, keeping the capture's timing and ACKing the host's "
                       "frames (--listen: the host connects to us; --port: we connect to the "
                       "host), or (--into-host) to the built-in host emulator in virtual time. "
                       "Ends with the run summary demo, host and sim print. Exit 0 when the run "
                       "is ok: played to the end with nothing lost (--into-host: judged as "
                       "host judges, Running Vision reached and held), else 1.")
    _input_options(r)
    where = r.add_mutually_exclusive_group(required=True)
    where.add_argument("--listen", dest="endpoint", action=ca.Endpoint,
                       metavar="tcp://HOST:PORT",
                       help="listen here for the host under test (port 0: any free port); "
                       "prints LISTEN URL on stderr")
    where.add_argument("--port", dest="endpoint", action=ca.Endpoint, metavar="URL",
                       help="connect to the host under test at tcp://HOST:PORT (socket:// too), "
                       "rfc2217://HOST:PORT or a tty/pty path")
    where.add_argument("--into-host", action="store_true",
                       help="feed the built-in host emulator in virtual time")
    r.set_defaults(port=None, listen=None, pty=False)
    r.add_argument("--duration", type=ca.number(0, 86_400, lo_open=True, unit="s"),
                   help="stop after S seconds of capture time, (0, 86400]")
    r.add_argument("--lead", type=ca.number(0, 3600, unit="s"), default=0.5, metavar="S",
                   help="--port: seconds between the host connecting and the first frame "
                   "(default 0.5)")
    r.add_argument("--json", action="store_true", help="end with one JSON object")
    s = sub.add_parser("sigrok-decoder", help="install the eyeq_spi decoder for sigrok/PulseView",
                       description="Write the eyeq_spi protocol decoder (stacked on sigrok's "
                       "spi) where libsigrokdecode looks for decoders.")
    s.add_argument("--install", metavar="DIR", nargs="?", const="",
                   help="decoders folder (default ~/.local/share/libsigrokdecode/decoders; "
                   "any other needs SIGROKDECODE_DIR=DIR)")


def _capture(args: argparse.Namespace, command: str, *, quiet: bool = False) -> Any:
    """The capture opened by the dissect pipeline with its release (``--sw`` overrides, one
    warning line when they disagree, unless ``quiet``: a first pass that only counts) and its
    tail (a pcapng cut inside a block is read up to its last whole block)."""
    from eyeq_spi.dissect.pipeline import DissectConfig, open_capture_file

    cap = open_capture_file(args.capture, DissectConfig(
        fmt=args.format, direction=args.direction, spi=_spi(args), sw=args.sw))
    if cap.release.warning and not quiet:
        print(f"eyeq-spi {command}: warning: {cap.release.warning}", file=sys.stderr,
              flush=True)
    return cap


def _tail_rc(command: str, path: str, cap: Any) -> int:
    """1 with one line on stderr when the reader left an incomplete last block, else 0."""
    if not cap.tail.ignored:
        return 0
    print(f"eyeq-spi {command}: {cap.tail.note(path)}", file=sys.stderr, flush=True)
    return 1


def run_export(args: argparse.Namespace) -> int:
    from eyeq_spi.bench.export import export, export_mdf
    from eyeq_spi.cli_progress import JobProgress

    if not (args.vcd or args.mdf or args.mcap):
        raise UsageError("give at least one of --vcd, --mdf, --mcap")
    transfers = bool(args.vcd or args.mcap)  # else MDF alone, from the pipeline's records
    total = _vcd_plan(args) if args.capture != "-" and transfers else None
    cap = _capture(args, "export")
    try:
        if transfers:
            with JobProgress(f"export {os.path.basename(args.capture)}", total,
                             unit="transfers", enabled=None if total else False) as bar:
                summary = export(cap.transfers, source=args.capture, sw=cap.release.key,
                                 vcd=args.vcd, mdf=args.mdf, mcap=args.mcap, spi=_spi(args),
                                 vcd_max_idle=args.vcd_max_idle, progress=bar.update)
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
    return _tail_rc("export", args.capture, cap)


def _vcd_plan(args: argparse.Namespace) -> int:
    """A first pass over the capture: how many transfers it holds (the progress bar's total)
    and, for --vcd, the VCD's estimated size, said on stderr before anything is written and
    refused above --vcd-max-size."""
    from eyeq_spi.logic.vcd_write import estimate_size

    cap = _capture(args, "export", quiet=True)
    n = nbytes = 0
    t0 = t1 = None
    try:
        for rec in cap.transfers:
            n += 1
            nbytes += len(rec.data)
            if rec.time is not None:
                t0 = rec.time if t0 is None else t0
                t1 = rec.time
    finally:
        cap.close()
    if args.vcd:
        span = (t1 - t0) if t0 is not None and t1 is not None else n * 5e-4
        if args.vcd_max_idle is not None:
            span = min(span, n * (args.vcd_max_idle + 15e-6))
        size = estimate_size(n, nbytes, span)
        mb = size / 1e6
        capture = os.path.getsize(args.capture) / 1e6
        if mb > args.vcd_max_size:
            raise UsageError(f"the VCD of {args.capture} would be about {mb:,.0f} MB "
                             f"({n:,} transfers, {nbytes * 8:,} bits; a VCD holds every clock "
                             f"edge); raise --vcd-max-size or export part of the capture")
        print(f"eyeq-spi: {os.path.basename(args.vcd)} will be about {mb:,.0f} MB "
              f"({capture:,.1f} MB capture; a VCD holds every clock edge)", file=sys.stderr)
    return n


def _spi(args: argparse.Namespace) -> Any:
    from eyeq_spi.logic.options import spi_options_from

    return spi_options_from(args)


def run_replay(args: argparse.Namespace) -> int:
    from eyeq_spi.bench.replay import replay_into_host, replay_to_port
    from eyeq_spi.report import format_summary

    if args.duration is not None and args.duration <= 0:
        raise UsageError("--duration must be positive")
    if args.pty:
        raise UsageError("replay takes --listen tcp://HOST:PORT or --port URL, not a pty")
    cap = _capture(args, "replay")
    try:
        if args.into_host:
            summary = replay_into_host(cap.transfers, sw=cap.release.key, duration=args.duration)
        else:
            if args.lead < 0:
                raise UsageError("--lead must not be negative")
            summary = replay_to_port(cap.transfers, args.listen or args.port,
                                     listen=bool(args.listen), duration=args.duration,
                                     lead=args.lead, sw=cap.release.key)
    finally:
        cap.close()
    if args.json:
        print(json.dumps(summary, sort_keys=True), flush=True)
    else:
        print(format_summary(summary), flush=True)
    rc = _tail_rc("replay", args.capture, cap)
    return 0 if summary["ok"] and not rc else 1


def run_sigrok_decoder(args: argparse.Namespace) -> int:
    from eyeq_spi.bench.sigrok_install import default_dir, install

    if args.install is None:
        raise UsageError("give --install [DIR]")
    target = install(args.install or None)
    hint = "" if not args.install or target.parent == default_dir() else \
        f" (run sigrok with SIGROKDECODE_DIR={target.parent})"
    print(f"installed the eyeq_spi decoder in {target}{hint}; use it as "
          "-P spi:cpol=0:cpha=1:...,eyeq_spi:direction=h2e")
    return 0
