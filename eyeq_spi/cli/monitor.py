"""``eyeq-spi monitor``: a live terminal view of demo, host, a replayed capture or a CAN bus."""

from __future__ import annotations

import argparse
import re
from typing import Any

from eyeq_spi.cli import inputs
from eyeq_spi.cli import options as opt
from eyeq_spi.errors import UsageError


def add_parser(sub: Any, name: str, help: str) -> None:
    parser = sub.add_parser(
        name, help=help,
        description="A live view (rich, plain ANSI, works over SSH): host state and "
        "transitions, message rates against nominal, link counters, E2E and counter errors, "
        "the current objects, lanes and signs. Ctrl-C stops it.")
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--demo", action="store_true",
                     help="host emulator against the embedded simulated EyeQ (as demo)")
    from eyeq_spi.cli.args import connect_address, number

    src.add_argument("--port", metavar="URL", type=connect_address,
                     help="host emulator against an EyeQ (as host)")
    src.add_argument("--replay", metavar="FILE",
                     help="a capture's EyeQ channel replayed into the host emulator (as replay "
                     "--into-host) in capture time")
    src.add_argument("--can-bus", metavar="INTERFACE:CHANNEL",
                     help="a live Mobileye CAN bus (virtual:NAME, socketcan:can0): one line per "
                     "ID with its cycle and newest signals, as cantools monitor (protocol: "
                     "--can-protocol)")
    parser.add_argument("--duration", type=opt.seconds,
                        help="seconds (default: 10 for --demo, no limit for --port and --can-bus, "
                        "the whole capture for --replay)")
    parser.add_argument("--virtual-time", action="store_true", help="--demo as fast as the CPU "
                                                                    "allows")
    parser.add_argument("--pace", type=number(0, 1e6), default=1.0, metavar="X",
                   help="--replay: X times real time (default 1; 0 = as fast as possible)")
    parser.add_argument("--passive", action="store_true",
                   help="--replay: show both channels as recorded, through the dissector, "
                   "instead of replaying into the host (a capture without the bring-up)")
    parser.add_argument("--refresh", type=number(5, 30, unit="Hz"), default=6.0, metavar="HZ",
                   help="screen redraws per second, 5..30 (default 6)")
    parser.add_argument("--screenshot", metavar="FILE",
                   help="also write the last screen to FILE.svg (a picture), .html or .txt")
    parser.add_argument("--screenshot-size", metavar="COLSxROWS", type=_size,
                   help="--screenshot: the screen as a terminal of that size shows it, e.g. "
                   "80x24 (default: the whole screen)")
    parser.add_argument("--nvm", metavar="FILE", help="--port: NVM file (default: in memory)")
    opt.include(parser, opt.capture_input(format_help="--replay: skip detection",
                                     direction_help="--replay: channel of an input without "
                                     "directions", sw_help=None))
    opt.include(parser, opt.scenario("monitor"), opt.foxglove())


def _size(text: str) -> tuple[int, int]:
    """``COLSxROWS`` of a terminal, at least 80x24."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not match or int(match.group(1)) < 80 or int(match.group(2)) < 24:
        raise argparse.ArgumentTypeError(f"give COLSxROWS of at least 80x24, not {text!r}")
    return int(match.group(1)), int(match.group(2))


def run(args: argparse.Namespace) -> int:
    from eyeq_spi.monitor.app import run as run_app

    if args.screenshot is not None:
        from eyeq_spi.monitor.app import check_screenshot

        check_screenshot(args.screenshot)  # before a long run
    if not args.replay:  # the capture-input options read a capture: --replay only
        for dest in ("format", "direction", "spi_mode", "bit_order", "channel_map", "signals"):
            if getattr(args, dest) not in (None, []):  # --spi-mode 0 is given too
                given = "--can-bus" if args.can_bus else "--port" if args.port else "--demo"
                raise UsageError(f"argument --{dest.replace('_', '-')}: applies to --replay, "
                                 f"not to monitor {given}")
    if args.can_bus:
        from eyeq_spi.monitor.can_bus import run_can_monitor

        if args.foxglove:
            raise UsageError("--foxglove serves the EyeQ's scene: not with --can-bus")
        run_can_monitor(args.can_bus, args.can_protocol, duration=args.duration,
                        refresh=args.refresh, screenshot=args.screenshot)
        return 0
    if args.port:
        opt.refuse_inapplicable(args, [opt.HOST], "monitor --port: the EyeQ there decides")
    elif args.replay:
        opt.refuse_inapplicable(args, [], "monitor --replay")
    if args.passive and not args.replay:
        raise UsageError("--passive goes with --replay")
    if args.replay and args.passive:
        from eyeq_spi.codec.message import MessageCodec
        from eyeq_spi.monitor.sources import DissectSource

        cf = inputs.open_input(args, "monitor", args.replay, pace_gc=False)
        source: Any = DissectSource(cf, MessageCodec(cf.release.key), speed=args.pace)
    elif args.replay:
        from eyeq_spi.monitor.sources import ReplaySource

        source = ReplaySource(inputs.open_input(args, "monitor", args.replay, pace_gc=False),
                              speed=args.pace,
                              duration=args.duration)
    elif args.demo:
        source = _demo_source(args)
    else:
        source = _host_source(args)
    live = _foxglove(args, source)
    try:
        run_app(source, refresh=args.refresh, screenshot=args.screenshot,
                screenshot_size=args.screenshot_size)
    finally:
        opt.foxglove_close(live)
    return inputs.tail_note("monitor", args.replay, getattr(source, "tail", None))


def _foxglove(args: argparse.Namespace, source: Any) -> Any:
    """``--foxglove``: the source's host (or, ``--passive``, its records) served live."""
    if not args.foxglove:
        return None
    view = getattr(source, "view", None)
    if view is not None:
        return opt.foxglove_feed(args, view.host)
    from eyeq_spi.foxglove.feed import Feed, RecordFeed

    live = RecordFeed(Feed(source.codec, opt.serve_foxglove(args)))
    source.on_record = live.add
    return live


def _demo_source(args: argparse.Namespace) -> Any:
    from eyeq_spi.monitor.sources import DemoSource

    emu, writer = opt.build_demo(args)
    return DemoSource(emu, 10.0 if args.duration is None else args.duration,
                      realtime=not args.virtual_time,
                      on_close=None if writer is None else writer.close)


def _host_source(args: argparse.Namespace) -> Any:
    from eyeq_spi.host.host import HostEmulator
    from eyeq_spi.live import capture_tap
    from eyeq_spi.monitor.sources import HostSource
    from eyeq_spi.phy.base import open_url
    from eyeq_spi.runner.realtime import RealTimeRunner

    host_cfg, nvm, scenario = opt.host_parts(args)
    host = HostEmulator(host_cfg, nvm=nvm, scenario=scenario, keep_rx_times=False)
    adapter = open_url(args.port)
    writer = opt.capture_writer(args)
    runner = RealTimeRunner(host, adapter, max_wait=0.01)
    runner.tap = capture_tap(writer, runner.clock(), "h2e", "e2h")

    def close() -> None:
        runner.close()
        adapter.close()
        nvm.save()
        if writer is not None:
            writer.close()

    return HostSource(host, runner, args.duration, on_close=close)

