#!/usr/bin/env python3
"""List every reconstruction recorded in specs/ (where the OCR'd seed was not read literally),
with its file, entry path and seed line. ``--count`` prints only the totals per file."""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[1]


def walk(node: Any, path: str, out: list[tuple[str, int | None, str]]) -> None:
    if isinstance(node, dict):
        if "reconstruction" in node:
            out.append((path, node.get("seed_line"), str(node["reconstruction"])))
        for k, v in node.items():
            if k != "reconstruction":
                label = node.get("name") if isinstance(node.get("name"), str) else None
                walk(v, f"{path}/{label or k}" if isinstance(v, (dict, list)) else path, out)
    elif isinstance(node, list):
        for i, v in enumerate(node):
            name = v.get("name") if isinstance(v, dict) else None
            walk(v, f"{path}[{name if name is not None else i}]", out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--count", action="store_true")
    args = ap.parse_args()
    totals: Counter[str] = Counter()
    for p in sorted((ROOT / "specs").rglob("*.yaml")):
        rows: list[tuple[str, int | None, str]] = []
        walk(yaml.safe_load(p.read_text()), "", rows)
        rel = str(p.relative_to(ROOT))
        totals[rel] = len(rows)
        if not args.count:
            for path, line, text in rows:
                print(f"{rel}{path} (seed line {line}): {' '.join(text.split())}")
    for rel, n in totals.items():
        print(f"{n:5d}  {rel}", file=sys.stderr if not args.count else sys.stdout)
    print(f"{sum(totals.values()):5d}  total", file=sys.stderr if not args.count else sys.stdout)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
