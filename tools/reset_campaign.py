#!/usr/bin/env python3
"""EyeQ reset campaign: N seeded random resets of the simulated EyeQ in Running
Vision; each must be noticed by the host, recover to Running Vision, hold it, and deliver no
stale data. Prints the figure (recovered of runs) and every failing seed. Exit 1 if any fails.

    python tools/reset_campaign.py --runs 1000 --jobs 2
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from eyeq_spi.faults.resets import ResetConfig, ResetOutcome, run_reset, summarise


def _chunk(seeds: list[int], max_offset: float) -> list[ResetOutcome]:
    cfg = ResetConfig(max_offset=max_offset)
    return [run_reset(s, cfg) for s in seeds]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--max-offset", type=float, default=2.0,
                    help="seconds of Running Vision before the reset, at most")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    seeds = list(range(args.first_seed, args.first_seed + args.runs))
    t0 = time.perf_counter()
    chunks = [seeds[i::args.jobs] for i in range(max(1, args.jobs))]
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as pool:
            parts = list(pool.map(_chunk, chunks, [args.max_offset] * len(chunks)))
    else:
        parts = [_chunk(seeds, args.max_offset)]
    outcomes = sorted((o for p in parts for o in p), key=lambda o: o.seed)
    report = summarise(outcomes, time.perf_counter() - t0)
    if args.json:
        print(json.dumps(report.as_dict(), default=str))
    else:
        print(f"{report.recovered} of {report.runs} resets recovered to Running Vision; "
              f"{report.stale_runs} runs with stale data ({report.stale_deliveries} messages); "
              f"{report.wall_s:.0f} s wall")
        for f in report.failures:
            print(f"  seed {f['seed']}: reset {f['offset'] * 1000:.1f} ms into Running Vision, "
                  f"host {f['host_state']}, EyeQ Main_State {f['eyeq_main_state']}, "
                  f"stale {f['stale_deliveries']}")
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
