#!/usr/bin/env python3
"""The floors of docs/performance.md in one run, this checkout against an older revision.

Each command runs as a fresh ``eyeq-spi`` process as a user starts it (bytecode and catalogue
caches warm after one untimed run), the two trees interleaved run by run so that a change of the
machine's load hits both. Per command: median CPU-s (user + system of the child) and spread
(min..max) of each tree, the floor's figure, and the ratio of the medians (this tree / before).

    python tools/bench_floors.py --before REV [--runs 5] [--only demo,stats,...]

Commands: ``demo`` (60 s virtual, full load: CPU-s per simulated s; floor ≤ 0.083),
``capture`` (the same with ``--capture``), ``stats``/``json``/``parquet`` (``dissect`` of a
60 s full-load capture made once by the tree before: frames per CPU-s; ``--stats`` floor
≥ 250 k, ``--json`` at most 1.5x the tree before), ``help`` (``--help``: ≤ 0.1 s), ``small``
(``dissect`` of 20 transfers in hex: ≤ 0.3 CPU-s), ``saleae2``/``vcd`` (``dissect --stats`` of
a 6 s full-load capture in Saleae Logic 2 CSV and in VCD, written by ``tools/bench_formats``'s
converters).
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import sys
import tempfile
from pathlib import Path

from bench_demo import FULL, cpu_of
from bench_startup import timing_env, trees_to_time

from eyeq_spi.capture.pcapng_io import read_pcapng


def _inputs(tmp: Path, env: dict[str, str]) -> dict[str, Path]:
    """The captures the commands read, made with this checkout."""
    from bench_formats import _formats

    cli = [sys.executable, "-m", "eyeq_spi.cli", "demo", "--virtual-time", *FULL]
    files = {"full60": tmp / "full60.pcapng", "full6": tmp / "full6.pcapng"}
    cpu_of([*cli, "--duration", "60", "--capture", str(files["full60"])], env, tmp)
    cpu_of([*cli, "--duration", "6", "--capture", str(files["full6"])], env, tmp)
    with files["full6"].open("rb") as fh:
        recs = list(read_pcapng(fh))
    converted = _formats(recs, files["full6"].read_bytes())
    for name in ("saleae2", "vcd"):
        files[name] = tmp / f"full6.{'csv' if name == 'saleae2' else 'vcd'}"
        files[name].write_bytes(converted[name][0])
    small = io.StringIO()
    for r in recs[:20]:
        small.write(f"{r.time:.6f} {r.direction} {r.data.hex()}\n")
    files["small"] = tmp / "small.hex"
    files["small"].write_text(small.getvalue())
    return files


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", metavar="REV", required=True)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--only", default="demo,capture,stats,json,parquet,help,small,saleae2,vcd")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        trees = trees_to_time(args.before, tmp)
        env = timing_env(tmp)
        files = _inputs(tmp, env)
        eyeq = [sys.executable, "-m", "eyeq_spi.cli"]
        demo = [*eyeq, "demo", "--virtual-time", "--json", "--duration", "60", *FULL]
        full60 = str(files["full60"])
        commands = {  # name: (argv, divisor: simulated seconds or frames, unit)
            "demo": (demo, 60.0, "CPU-s per simulated s"),
            "capture": ([*demo, "--capture", str(tmp / "c.pcapng")], 60.0,
                        "CPU-s per simulated s"),
            "stats": ([*eyeq, "dissect", full60, "--stats"], 0.0, "frames per CPU-s"),
            "json": ([*eyeq, "dissect", full60, "--json"], 0.0, "frames per CPU-s"),
            "parquet": ([*eyeq, "dissect", full60, "--parquet", str(tmp / "t")], 0.0,
                        "frames per CPU-s"),
            "help": ([*eyeq, "--help"], 1.0, "CPU-s"),
            "small": ([*eyeq, "dissect", str(files["small"])], 1.0, "CPU-s"),
            "saleae2": ([*eyeq, "dissect", str(files["saleae2"]), "--stats"], 1.0, "CPU-s"),
            "vcd": ([*eyeq, "dissect", str(files["vcd"]), "--stats"], 1.0, "CPU-s"),
        }
        chosen = [c for c in args.only.split(",") if c in commands]
        with files["full60"].open("rb") as fh:
            frames = sum(1 for _ in read_pcapng(fh))
        print(f"load average at the start: {os.getloadavg()[0]:.1f}; full60: {frames} frames",
              flush=True)
        for _, tree in trees:  # warm-up: bytecode and catalogue caches, page cache
            for name in chosen:
                argv = commands[name][0]
                cpu_of(argv if name not in ("demo", "capture") else [*argv[:6], "--duration",
                       "0.5"], {**env, "PYTHONPATH": str(tree)}, tmp, check=False)
        cpu: dict[tuple[str, str], list[float]] = {}
        for _ in range(args.runs):
            for name in chosen:
                for label, tree in trees:
                    cpu.setdefault((name, label), []).append(
                        cpu_of(commands[name][0], {**env, "PYTHONPATH": str(tree)}, tmp))
        print(f"load average at the end: {os.getloadavg()[0]:.1f}\n")
        print("| command | figure | before: median (min..max) | after: median (min..max) | "
              "after / before |\n|---|---|---|---|---|")
        for name in chosen:
            _, div, unit = commands[name]
            cells, meds = [], []
            for label, _ in trees:
                v = [frames / x if div == 0.0 else x / div for x in cpu[(name, label)]]
                meds.append(statistics.median(v))
                fmt = "{:,.0f}" if div == 0.0 else "{:.4f}"
                cells.append(f"{fmt.format(meds[-1])} ({fmt.format(min(v))}.."
                             f"{fmt.format(max(v))})")
            print(f"| {name} | {unit} | {cells[0]} | {cells[1]} | {meds[1] / meds[0]:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
