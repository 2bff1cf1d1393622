"""The whole ``demo --virtual-time`` at full load (15 objects, 20 signs, 15 light spots) as a user
runs it: CPU (user + system) of the process per simulated second, without and with
``--capture``, the capture's share as the difference of the two.

    python tools/bench_demo.py [--runs N] [--duration S] [--before REV]

Each run of each variant is a fresh process (after one warm-up run that fills the bytecode and
catalogue caches); the table gives the median and spread (min..max) of the CPU per simulated
second and the median as 128-byte ``binascii.crc_hqx`` calls of an in-run baseline (the figures
move with the machine's load, the ratio less). ``--before REV`` also runs ``git archive REV`` of
this repository; the runs of both trees are interleaved so that a change of load hits both.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from bench import crc_baseline_us
from bench_startup import timing_env, trees_to_time

FULL = ["--objects", "15", "--signs", "20", "--light-spots", "15"]


def cpu_of(argv: list[str], env: dict[str, str], cwd: Path, check: bool = True) -> float:
    """CPU seconds (user + system) of one run of ``argv`` as a child process, run from ``cwd``
    (never the repository: ``python -m`` would import the package from there)."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   check=check, cwd=cwd)
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--duration", type=float, default=60.0, help="simulated seconds per run")
    ap.add_argument("--before", metavar="REV", help="also time this git revision")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        trees = trees_to_time(args.before, tmp)
        env = timing_env(tmp)
        demo = [sys.executable, "-m", "eyeq_spi.cli", "demo", "--virtual-time", "--json",
                "--duration", f"{args.duration:g}", *FULL]
        variants = {"demo": demo, "demo --capture": [*demo, "--capture", str(tmp / "c.pcapng")]}
        cpu: dict[tuple[str, str], list[float]] = {}
        crc = [crc_baseline_us()]
        print(f"load average at the start: {os.getloadavg()[0]:.1f}", flush=True)
        for _, tree in trees:  # warm-up: bytecode and catalogue caches, page cache
            cpu_of([*demo[:6], "--duration", "0.5"], {**env, "PYTHONPATH": str(tree)}, tmp,
                   check=False)
        for _ in range(args.runs):
            for name, tree in trees:
                for label, argv in variants.items():
                    cpu.setdefault((name, label), []).append(
                        cpu_of(argv, {**env, "PYTHONPATH": str(tree)}, tmp))
            crc.append(crc_baseline_us())
        base = statistics.median(crc)
        print(f"baseline: one crc_hqx over 128 bytes {base:.3f} µs (median of {len(crc)})\n")
        print("| tree | command | CPU-ms per simulated s | spread | crc_hqx-equivalents |\n"
              "|---|---|---|---|---|")
        for (name, label), v in cpu.items():
            per = [x / args.duration * 1e3 for x in v]
            med = statistics.median(per)
            print(f"| {name} | {label} | {med:.1f} | {min(per):.1f}–{max(per):.1f} | "
                  f"{med / base * 1e3:,.0f} |")
        for name, _ in trees:
            diff = [(c - p) / args.duration * 1e3 for c, p in zip(
                cpu[(name, "demo --capture")], cpu[(name, "demo")], strict=True)]
            print(f"| {name} | the capture (difference, run by run) | "
                  f"{statistics.median(diff):.1f} | {min(diff):.1f}–{max(diff):.1f} | |")
        print(f"\nload average at the end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
