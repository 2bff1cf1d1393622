"""``eyeq-spi plot`` (pictures of a capture) and ``eyeq-spi monitor`` (a live terminal view)."""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path
from typing import Any

from eyeq_spi.errors import UsageError

# shared options that only the simulated EyeQ uses, and those only the host emulator uses
SIM_ONLY = ("seed", "objects", "signs", "light_spots", "boot_fail", "boot_test_bits",
            "corrupt_eeprom", "fatal", "reply_delay", "drop_reply", "reset_at", "stop_dasp")
HOST_ONLY = ("speed", "scenario", "camera_only_aeb", "ack_timeout", "transmit_timeout",
             "capture")


_FORMATS = ("raw", "hex", "pcapng", "saleae2", "saleae1", "vcd")  # as dissect reads


def add_plot_parser(sub: Any) -> None:
    p = sub.add_parser(
        "plot", help="bird's-eye scene, stream timing or link behaviour of a capture",
        description="Draw a capture (read through the dissector) as PNG, SVG or a "
        "self-contained HTML file; --animate writes a GIF or an HTML player. Needs the plot "
        "extra: pip install 'eyeq-spi[plot]'.")
    p.add_argument("capture", metavar="CAPTURE", help="pcapng, hex or raw capture")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--birdseye", action="store_true",
                      help="objects, lanes and signs seen from above")
    what.add_argument("--timing", action="store_true",
                      help="inter-arrival time of each message against its nominal rate")
    what.add_argument("--link", action="store_true",
                      help="frames/s by kind, NAKs by reason, CRC errors and aborts over time")
    p.add_argument("-o", "--output", metavar="FILE",
                   help="FILE.png, .svg or .html (--animate: .gif or .html); default: "
                   "CAPTURE_<kind>.png (.gif when animated) beside the capture")
    p.add_argument("--at", type=float, metavar="T",
                   help="--birdseye: the scene at T s from the capture start (default: the end)")
    p.add_argument("--animate", action="store_true", help="--birdseye over the whole window")
    p.add_argument("--fps", type=float, default=5.0, help="--animate: frames per capture second")
    p.add_argument("--max-frames", type=int, default=600, help="--animate: at most N frames")
    p.add_argument("--range", dest="range_m", type=float, metavar="M",
                   help="--birdseye: metres ahead (default: fitted)")
    p.add_argument("--lateral", dest="lateral_m", type=float, metavar="M",
                   help="--birdseye: metres to each side (default: fitted)")
    p.add_argument("--name", metavar="REGEX",
                   help="--timing: only messages whose name matches (default: all periodic)")
    p.add_argument("--bin", dest="bin_ms", type=float, default=100.0, metavar="MS",
                   help="--link: time bin (default 100 ms)")
    p.add_argument("--start", type=float, default=0.0, metavar="S", help="window start, s")
    p.add_argument("--end", type=float, default=math.inf, metavar="S", help="window end, s")
    from eyeq_spi.logic.options import add_spi_arguments

    p.add_argument("--format", choices=_FORMATS, help="skip detection")
    p.add_argument("--direction", choices=("h2e", "e2h"),
                   help="channel of an input without directions")
    add_spi_arguments(p)
    p.add_argument("--sw", help="SW release of the traffic (default: the one the capture "
                   "records or shows, else the newest)")

    from eyeq_spi.cli_run import add_shared_options

    m = sub.add_parser(
        "monitor", help="live terminal view of demo, host or a replayed capture",
        description="A live view (rich, plain ANSI, works over SSH): host state and "
        "transitions, message rates against nominal, link counters, E2E and counter errors, "
        "the current objects, lanes and signs. Ctrl-C stops it. Needs rich: "
        "pip install 'eyeq-spi[monitor]'.")
    src = m.add_mutually_exclusive_group(required=True)
    src.add_argument("--demo", action="store_true",
                     help="host emulator against the embedded simulated EyeQ (as demo)")
    from eyeq_spi.cli_args import connect_address

    src.add_argument("--port", metavar="URL", type=connect_address,
                     help="host emulator against an EyeQ (as host)")
    src.add_argument("--replay", metavar="FILE",
                     help="a capture's EyeQ channel replayed into the host emulator (as replay "
                     "--into-host) in capture time")
    src.add_argument("--can-bus", metavar="INTERFACE:CHANNEL",
                     help="a live Mobileye CAN bus (virtual:NAME, socketcan:can0): one line per "
                     "ID with its cycle and newest signals, as cantools monitor (protocol: "
                     "--can-protocol)")
    m.add_argument("--duration", type=float, help="seconds (default: 10 for --demo, no limit "
                   "for --port and --can-bus, the whole capture for --replay)")
    m.add_argument("--virtual-time", action="store_true", help="--demo as fast as the CPU allows")
    m.add_argument("--pace", type=float, default=1.0, metavar="X",
                   help="--replay: X times real time (default 1; 0 = as fast as possible)")
    m.add_argument("--passive", action="store_true",
                   help="--replay: show both channels as recorded, through the dissector, "
                   "instead of replaying into the host (a capture without the bring-up)")
    m.add_argument("--refresh", type=float, default=6.0, metavar="HZ",
                   help="screen redraws per second, 5..30 (default 6)")
    m.add_argument("--screenshot", metavar="FILE",
                   help="also write the last screen to FILE.svg (a picture), .html or .txt")
    m.add_argument("--screenshot-size", metavar="COLSxROWS", type=_size,
                   help="--screenshot: the screen as a terminal of that size shows it, e.g. "
                   "80x24 (default: the whole screen)")
    m.add_argument("--nvm", metavar="FILE", help="--port: NVM file (default: in memory)")
    m.add_argument("--format", choices=_FORMATS, help="--replay: skip detection")
    m.add_argument("--direction", choices=("h2e", "e2h"),
                   help="--replay: channel of an input without directions")
    add_spi_arguments(m)
    add_shared_options(m)
    m.set_defaults(side_defaults={d: m.get_default(d) for d in SIM_ONLY + HOST_ONLY})


def _size(text: str) -> tuple[int, int]:
    """``COLSxROWS`` of a terminal, at least 80x24."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or int(m.group(1)) < 80 or int(m.group(2)) < 24:
        raise argparse.ArgumentTypeError(f"give COLSxROWS of at least 80x24, not {text!r}")
    return int(m.group(1)), int(m.group(2))


def _default_output(args: argparse.Namespace, kind: str) -> str:
    cap = Path(args.capture)
    suffix = ".gif" if args.animate else ".png"
    return str(cap.with_name(f"{cap.stem}_{kind}{suffix}"))


def run_plot(args: argparse.Namespace) -> int:
    from eyeq_spi.codec.message import MessageCodec
    from eyeq_spi.plot.collect import Collector, Window, collect_capture
    from eyeq_spi.plot.output import check_output, mpl, save_animation, save_figure

    kind = "birdseye" if args.birdseye else "timing" if args.timing else "link"
    if (args.at is not None or args.animate) and not args.birdseye:
        raise UsageError("--at and --animate go with --birdseye")
    if args.at is not None and args.animate:
        raise UsageError("give --at or --animate, not both")
    for name in ("fps", "bin_ms", "range_m", "lateral_m"):
        v = getattr(args, name)
        if v is not None and not (0 < v < 1e6):
            raise UsageError(f"--{name.split('_')[0]} must be positive")
    if args.max_frames < 1 or args.start < 0 or not args.end > args.start:
        raise UsageError("need --max-frames >= 1 and 0 <= --start < --end")
    try:
        name_re = re.compile(args.name) if args.name else None
    except re.error as exc:
        raise UsageError(f"--name: bad regular expression: {exc}") from None
    out = args.output or _default_output(args, kind)
    check_output(out, animated=args.animate)
    mpl()  # fail before reading a large capture when matplotlib is missing
    cf = _open_capture(args, args.capture, "plot")
    codec = MessageCodec(cf.release.key)
    window = Window(args.start, args.end)
    col = Collector(codec, window, timing=args.timing, link=args.link,
                    link_bin=args.bin_ms / 1000.0,
                    at=(args.at if args.at is not None else math.inf) if args.birdseye
                    and not args.animate else None,
                    fps=args.fps if args.animate else None, max_frames=args.max_frames)
    try:
        data = collect_capture(cf, col)
    finally:
        cf.close()
    if name_re is not None:
        data.streams = {k: v for k, v in data.streams.items() if name_re.search(k)}
    title = f"{Path(args.capture).name}: {kind}"
    if args.birdseye:
        from eyeq_spi.plot.birdseye import animation, birdseye

        if args.animate:
            anim = animation(data.frames, args.fps, args.range_m, args.lateral_m)
            save_animation(anim, out, args.fps, title)
        else:
            assert data.scene is not None
            save_figure(birdseye(data.scene, args.range_m, args.lateral_m), out, title)
    else:
        from eyeq_spi.plot.charts import link_figure, timing_figure

        fig = timing_figure(data)[0] if args.timing else link_figure(data)
        save_figure(fig, out, title)
    print(f"wrote {out}")
    return _tail_note("plot", args.capture, cf.tail)


def _open_capture(args: argparse.Namespace, path: str, command: str) -> Any:
    """The capture opened by the dissect pipeline with the release it is read with (the
    capture's own unless ``--sw``), with the one-line warning when they disagree."""
    from eyeq_spi.dissect.pipeline import DissectConfig, open_capture_file
    from eyeq_spi.logic.options import spi_options_from

    cf = open_capture_file(path, DissectConfig(
        fmt=args.format, direction=getattr(args, "direction", None),
        spi=spi_options_from(args), sw=args.sw, pace_gc=command != "monitor"))
    if cf.release.warning:
        print(f"eyeq-spi {command}: warning: {cf.release.warning}", file=sys.stderr,
              flush=True)
    return cf


def _tail_note(command: str, path: str, tail: Any) -> int:
    """Exit 1 with one line when the reader left an incomplete last block, else 0."""
    if tail is None or not tail.ignored:
        return 0
    print(f"eyeq-spi {command}: {tail.note(path)}", file=sys.stderr, flush=True)
    return 1


def run_monitor(args: argparse.Namespace) -> int:
    from eyeq_spi.monitor.app import run

    if args.duration is not None and args.duration <= 0:
        raise UsageError("--duration must be positive")
    if not 0 <= args.pace <= 1e6:
        raise UsageError("--pace must be >= 0")
    if args.screenshot is not None:
        from eyeq_spi.monitor.app import check_screenshot

        check_screenshot(args.screenshot)  # before a long run
    if args.can_bus:
        from eyeq_spi.monitor.app import MAX_REFRESH, MIN_REFRESH
        from eyeq_spi.monitor.can_bus import run_can_monitor

        if not MIN_REFRESH <= args.refresh <= MAX_REFRESH:
            raise UsageError(f"--refresh must be {MIN_REFRESH:g}..{MAX_REFRESH:g} Hz")
        run_can_monitor(args.can_bus, args.can_protocol, duration=args.duration,
                        refresh=args.refresh, screenshot=args.screenshot)
        return 0
    unused = SIM_ONLY if args.port else SIM_ONLY + HOST_ONLY if args.replay else ()
    for dest in unused:
        if hasattr(args, dest) and getattr(args, dest) != args.side_defaults.get(dest):
            src = "--port" if args.port else "--replay"
            raise UsageError(f"--{dest.replace('_', '-')} does not apply to {src}")
    if args.passive and not args.replay:
        raise UsageError("--passive goes with --replay")
    if args.replay and args.passive:
        from eyeq_spi.codec.message import MessageCodec
        from eyeq_spi.monitor.sources import DissectSource

        cf = _open_capture(args, args.replay, "monitor")
        source: Any = DissectSource(cf, MessageCodec(cf.release.key), speed=args.pace)
    elif args.replay:
        from eyeq_spi.monitor.sources import ReplaySource

        source = ReplaySource(_open_capture(args, args.replay, "monitor"), speed=args.pace,
                              duration=args.duration)
    elif args.demo:
        source = _demo_source(args)
    else:
        source = _host_source(args)
    run(source, refresh=args.refresh, screenshot=args.screenshot,
        screenshot_size=args.screenshot_size)
    return _tail_note("monitor", args.replay, getattr(source, "tail", None))


def _demo_source(args: argparse.Namespace) -> Any:
    from eyeq_spi.cli_run import build_demo
    from eyeq_spi.monitor.sources import DemoSource

    emu, writer = build_demo(args)
    source = DemoSource(emu, 10.0 if args.duration is None else args.duration,
                        realtime=not args.virtual_time)
    if writer is not None:
        source.close = writer.close  # type: ignore[method-assign]
    return source


def _host_source(args: argparse.Namespace) -> Any:
    import gc

    from eyeq_spi.cli_run import capture_writer, host_parts
    from eyeq_spi.host.host import HostEmulator
    from eyeq_spi.monitor.sources import HostSource
    from eyeq_spi.phy.base import open_url
    from eyeq_spi.runner.realtime import RealTimeRunner

    host_cfg, nvm, scenario = host_parts(args)
    host = HostEmulator(host_cfg, nvm=nvm, scenario=scenario, keep_rx_times=False)
    adapter = open_url(args.port)
    writer = capture_writer(args)
    runner = RealTimeRunner(host, adapter, max_wait=0.01)
    if writer is not None:
        start = runner.clock()

        def tap(kind: str, t: float, transfer: bytes) -> None:
            writer.write("h2e" if kind == "tx" else "e2h", t - start, transfer)

        runner.tap = tap
    gc.freeze()  # as `host` does: the catalogue and layouts live forever

    def close() -> None:
        adapter.close()
        nvm.save()
        if writer is not None:
            writer.close()

    return HostSource(host, runner, args.duration, on_close=close)

