"""``eyeq-spi replay``: a capture's EyeQ channel played to a host under test or to the built-in
host emulator."""

from __future__ import annotations

import argparse
from typing import Any

from eyeq_spi.cli import inputs


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import args as ca
    from eyeq_spi.cli import options as opt

    parser = sub.add_parser(name, help=help, parents=[opt.capture_input()],
                       description="Play a capture's EyeQ channel (e2h) to a host under test "
                       "in real time, in the capture's timing, ACKing the host's frames, or "
                       "(--into-host) to the built-in host emulator in virtual time; end with the "
                       "run summary. Exit 0 when played to the end with nothing lost "
                       "(--into-host: Running Vision reached and held), else 1.")
    inputs.add_capture_argument(parser)
    where = parser.add_mutually_exclusive_group(required=True)
    ca.add_endpoints(parser, where,
                     listen="listen here for the host under test (port 0: any free port); "
                     "prints LISTEN URL on stderr",
                     port="connect to the host under test at tcp://HOST:PORT (socket:// too), "
                     "rfc2217://HOST:PORT or a tty/pty path")
    where.add_argument("--into-host", action="store_true",
                       help="feed the built-in host emulator in virtual time (with "
                       "--foxglove: at the capture's pace)")
    parser.add_argument("--duration", type=opt.seconds,
                   help="stop after S seconds of capture time, (0, 86400]")
    parser.add_argument("--lead", type=ca.number(0, 3600, unit="s"), default=0.5, metavar="S",
                   help="--port: seconds between the host connecting and the first frame "
                   "(default 0.5)")
    opt.include(parser, opt.json_out(), opt.foxglove())


def run(args: argparse.Namespace) -> int:
    from eyeq_spi.cli import options as opt
    from eyeq_spi.interop.replay import replay_into_host, replay_to_port

    cap = inputs.open_input(args, "replay")
    sink = opt.serve_foxglove(args)
    live: Any = None
    try:
        if args.into_host:
            def watch(host: Any) -> None:  # --foxglove: the replayed host, at the capture's pace
                from eyeq_spi.foxglove.live import HostFeed

                nonlocal live
                live = HostFeed(host, sink)

            summary = replay_into_host(cap.transfers, sw=cap.release.key, duration=args.duration,
                                       realtime=sink is not None,
                                       on_host=watch if sink is not None else None)
        else:
            if sink is not None:  # --foxglove: the messages as they are played
                from eyeq_spi.codec.message import MessageCodec
                from eyeq_spi.foxglove.live import MessageFeed

                live = MessageFeed(MessageCodec(cap.release.key), sink)
            summary = replay_to_port(cap.transfers, args.listen or args.port,
                                     listen=bool(args.listen), duration=args.duration,
                                     lead=args.lead, sw=cap.release.key,
                                     on_message=live.message if live is not None else None)
    finally:
        cap.close()
        if live is not None:
            opt.foxglove_close(live)
        elif sink is not None:
            sink.close()
    opt.print_summary(summary, args.json)
    rc = inputs.tail_note("replay", args.capture, cap.tail)
    return 0 if summary["ok"] and not rc else 1
