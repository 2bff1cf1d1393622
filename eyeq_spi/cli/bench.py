"""``eyeq-spi bench doctor``: check a rig of SPI adapters before a run (docs/bench.md)."""

from __future__ import annotations

import argparse
import contextlib
import json
from typing import Any


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import args as ca
    from eyeq_spi.cli import options as opt

    bench = sub.add_parser(name, help=help)
    bench_sub = bench.add_subparsers(dest="bench_command", required=True,
                                     parser_class=type(bench))
    doc = bench_sub.add_parser(
        "doctor", help="frames through every channel: bytes, bit order, mode, ACK latency",
        description="Send frames through both channels of a rig and answer each at once, as "
        "the link answers a DATA frame with an ACK: check every byte, the bit order and the "
        "SPI mode, and measure the reply latency (slave read to master write) and the round "
        "trip against the 10 ms ackTimeout. One verdict line; exit 0 if the rig is fit for a "
        "live EyeQ, 1 if not.")
    doc.add_argument("side", metavar="SIDE", type=ca.spi_side,
                     help="our channels: MASTER_URL,SLAVE_URL or a bench.toml; alone, its "
                     "master must be wired to its own slave (a loop)")
    doc.add_argument("--peer", metavar="SIDE", type=ca.spi_side,
                     help="a second side wired to the first (each master to the other's "
                     "slave): frames go both ways")
    doc.add_argument("--frames", type=ca.integer(1, 100_000), default=200, metavar="N",
                     help="frames per direction (default 200)")
    opt.include(doc, opt.json_out(), opt.rt_priority("the replies"))


def run(args: argparse.Namespace) -> int:
    from eyeq_spi.phy.base import open_url
    from eyeq_spi.phy.doctor import examine, verdict_line
    from eyeq_spi.runner.sched import realtime

    with contextlib.ExitStack() as stack:
        # as a live run would: the adapters' threads start under this policy
        stack.enter_context(realtime(args.rt_priority))
        side = stack.enter_context(open_url(args.side))
        peer = stack.enter_context(open_url(args.peer)) if args.peer else None
        report = examine(side, peer, frames=args.frames)  # type: ignore[arg-type]
    if args.json:
        print(json.dumps(report, sort_keys=True))
    else:
        print(f"bench doctor: {verdict_line(report)}")
    return 0 if report["fit"] else 1
