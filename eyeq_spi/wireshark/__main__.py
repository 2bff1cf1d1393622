"""``python -m eyeq_spi.wireshark [-o FILE] [--sw V]``: write the generated Lua dissector."""

from __future__ import annotations

import argparse
import sys

from eyeq_spi.errors import EyeqError
from eyeq_spi.wireshark.lua_gen import generate_lua


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m eyeq_spi.wireshark",
                                 description="Generate the Wireshark Lua dissector.")
    ap.add_argument("-o", "--output", help="file to write (default: stdout)")
    ap.add_argument("--sw", help="read every capture as this SW release (default: each "
                                    "capture's own)")
    args = ap.parse_args(argv)
    try:
        text = generate_lua(args.sw)
    except (EyeqError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.output:
        try:
            with open(args.output, "w", encoding="utf-8") as fh:
                fh.write(text)
        except OSError as exc:
            print(f"error: cannot write {args.output}: {exc}", file=sys.stderr)
            return 2
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
