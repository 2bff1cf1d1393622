"""``eyeq-spi plot``: pictures of a capture (bird's-eye scene, stream timing, link behaviour)."""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path
from typing import Any

from eyeq_spi.cli import inputs
from eyeq_spi.errors import UsageError


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import args as ca
    from eyeq_spi.cli import options as opt

    parser = sub.add_parser(
        name, help=help,
        description="Draw a capture (read through the dissector) as PNG, SVG or a "
        "self-contained HTML file; --animate writes a GIF or an HTML player. Needs the plot "
        "extra: pip install 'eyeq-spi[plot]'.")
    parser.add_argument("capture", metavar="CAPTURE",
                   help=f"capture file: {', '.join(opt.FORMATS)} (as eyeq-spi dissect reads)")
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--birdseye", action="store_true",
                      help="objects, lanes and signs seen from above")
    what.add_argument("--timing", action="store_true",
                      help="inter-arrival time of each message against its nominal rate")
    what.add_argument("--link", action="store_true",
                      help="frames/s by kind, NAKs by reason, CRC errors and aborts over time")
    parser.add_argument("-o", "--output", metavar="FILE",
                   help="FILE.png, .svg or .html (--animate: .gif or .html); default: "
                   "CAPTURE_<kind>.png (.gif when animated) beside the capture")
    parser.add_argument("--at", type=float, metavar="T",
                   help="--birdseye: the scene at T s from the capture start (default: the end)")
    parser.add_argument("--animate", action="store_true", help="--birdseye over the whole window")
    positive = ca.number(0, 1e6, lo_open=True)
    parser.add_argument("--fps", type=positive, default=5.0,
                        help="--animate: frames per capture second")
    parser.add_argument("--max-frames", type=ca.integer(1, 10**6), default=600,
                        help="--animate: at most N frames")
    parser.add_argument("--range", dest="range_m", type=positive, metavar="M",
                   help="--birdseye: metres ahead (default: fitted)")
    parser.add_argument("--lateral", dest="lateral_m", type=positive, metavar="M",
                   help="--birdseye: metres to each side (default: fitted)")
    parser.add_argument("--name", metavar="REGEX", type=ca.regex,
                   help="--timing: only messages whose name matches (default: all periodic)")
    parser.add_argument("--bin", dest="bin_ms", type=positive, default=100.0, metavar="MS",
                   help="--link: time bin (default 100 ms)")
    parser.add_argument("--start", type=ca.number(0, 1e9), default=0.0, metavar="S",
                        help="window start, s")
    parser.add_argument("--end", type=float, default=math.inf, metavar="S", help="window end, s")
    opt.include(parser, opt.capture_input())


def run(args: argparse.Namespace) -> int:
    from eyeq_spi.codec.message import MessageCodec
    from eyeq_spi.plot.collect import Collector, Window, collect_capture
    from eyeq_spi.plot.figures import check_output, mpl, save_animation, save_figure

    kind = "birdseye" if args.birdseye else "timing" if args.timing else "link"
    if (args.at is not None or args.animate) and not args.birdseye:
        raise UsageError("--at and --animate go with --birdseye")
    if args.at is not None and args.animate:
        raise UsageError("give --at or --animate, not both")
    if not args.end > args.start:
        raise UsageError("need --start < --end")
    name_re = re.compile(args.name) if args.name else None
    capture = Path(args.capture)  # the default output: CAPTURE_<kind>.png (.gif) beside it
    out = args.output or str(capture.with_name(
        f"{capture.stem}_{kind}{'.gif' if args.animate else '.png'}"))
    check_output(out, animated=args.animate)
    mpl()  # fail before reading a large capture when matplotlib is missing
    cf = inputs.open_input(args, "plot")
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
    if args.birdseye and args.at is not None and data.has_time and args.at > data.end:
        raise UsageError(f"--at {args.at:g}: after the last record read, at {data.end:.2f} s "
                         f"(the capture spans 0 to {data.end:.2f} s since its first transfer)")
    if name_re is not None:
        data.streams = {k: value for k, value in data.streams.items() if name_re.search(k)}
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
    return inputs.tail_note("plot", args.capture, cf.tail)
