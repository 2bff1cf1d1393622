"""``eyeq-spi wireshark``: the Wireshark Lua dissector generated from ``specs/``."""

from __future__ import annotations

import argparse
import sys
from typing import Any


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import args as ca
    from eyeq_spi.cli import options as opt

    parser = sub.add_parser(name, help=help)
    parser.add_argument("--output", "-o", metavar="FILE.lua", type=ca.output_file,
                   help="write the dissector here (default: standard output)")
    opt.add_sw(parser, "read every capture as this SW release: the default of the dissector's "
               "eyeq_spi.sw preference (default: auto, each capture's own release)")


def run(args: argparse.Namespace) -> int:
    from eyeq_spi.plot.figures import write_file
    from eyeq_spi.wireshark.lua_gen import generate_lua

    text = generate_lua(args.sw)
    if args.output in (None, "-"):
        sys.stdout.write(text)
        sys.stdout.flush()
        return 0
    write_file(args.output, text)
    print(f"wrote {args.output} ({len(text.splitlines())} lines)\n"
          f"use it with: wireshark -X lua_script:{args.output}\n"
          "or copy it to your personal Lua plugins folder (Help > About Wireshark > Folders)")
    return 0
