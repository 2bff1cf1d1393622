"""``eyeq-spi sigrok-decoder``: install the eyeq_spi protocol decoder for sigrok/PulseView."""

from __future__ import annotations

import argparse
from typing import Any

from eyeq_spi.errors import UsageError


def add_parser(sub: Any, name: str, help: str) -> None:
    parser = sub.add_parser(name, help=help,
                       description="Write the eyeq_spi protocol decoder (stacked on sigrok's "
                       "spi) where libsigrokdecode looks for decoders.")
    parser.add_argument("--install", metavar="DIR", nargs="?", const="",
                   help="decoders folder (default ~/.local/share/libsigrokdecode/decoders; "
                   "any other needs SIGROKDECODE_DIR=DIR)")


def run(args: argparse.Namespace) -> int:
    from eyeq_spi.interop.sigrok_install import default_dir, install

    if args.install is None:
        raise UsageError("give --install [DIR]")
    target = install(args.install or None)
    hint = "" if not args.install or target.parent == default_dir() else \
        f" (run sigrok with SIGROKDECODE_DIR={target.parent})"
    print(f"installed the eyeq_spi decoder in {target}{hint}; use it as "
          "-P spi:cpol=0:cpha=1:...,eyeq_spi:direction=h2e")
    return 0
