"""``eyeq-spi spec list`` and ``eyeq-spi spec show``: the message catalogue built from
``specs/``."""

from __future__ import annotations

import argparse
from typing import Any

from eyeq_spi.errors import UsageError


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import options as opt

    spec = sub.add_parser(name, help=help)
    spec_sub = spec.add_subparsers(dest="spec_command", required=True,
                                   parser_class=type(spec))
    sl = spec_sub.add_parser("list", help="list messages, MESP functions, init messages, structs")
    opt.add_sw(sl, "SW release for sizes (default: newest)")
    ss = spec_sub.add_parser("show", help="offsets, sizes, types and CRC coverage of one entry")
    ss.add_argument("name", help="message, struct, init message, MESP function or enum: name "
                    "(any case, or part of one) or data ID such as 0xE4")
    opt.add_sw(ss, "SW release, e.g. 9.0, 8.1 or sw5 (default: newest)")


def run(args: argparse.Namespace) -> int:
    from eyeq_spi.catalog.messages import catalog
    from eyeq_spi.codec.describe import spec_list, spec_show

    cat = catalog()
    sw = cat.sw(args.sw)
    if args.spec_command == "list":
        text = spec_list(cat, sw)
    else:
        from eyeq_spi.cli.args import spec_entry

        try:
            name = spec_entry(args.name)
        except argparse.ArgumentTypeError as exc:
            raise UsageError(f"argument NAME: {exc}") from None
        text = spec_show(cat, name, sw)
    print(text)
    return 0
