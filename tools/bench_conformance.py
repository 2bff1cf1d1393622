#!/usr/bin/env python3
"""Conformance suite figures.

1. One ``--builtin`` run of the whole suite, per DUT kind, in CPU seconds, against an in-run
   baseline: the plain emulator (our host and our simulated EyeQ, the same light scene, no
   tester shim, no trace) for the same seconds of virtual time as the suite's sessions. The
   ratio is what the tester, the fault shim, the trace and the judges cost on top.
2. The mutant matrix (every broken variant runs the whole suite) as CI runs it: a pool of two
   processes, wall seconds, against the sum of the CPU the variants took (the sequential
   cost) of the same run.

Each figure of part 1 is the median of ``--repeat`` runs with its spread (min..max).
``python tools/bench_conformance.py [--repeat 3] [--no-matrix]``
"""

from __future__ import annotations

import argparse
import multiprocessing
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from eyeq_spi.conformance import suite
from eyeq_spi.conformance.mutants import MUTANTS, builtin_eyeq_config
from eyeq_spi.conformance.suite import Options, run
from eyeq_spi.emulator import build


def suite_run(dut: str) -> tuple[float, float]:
    """(CPU seconds, virtual seconds of all sessions) of one --builtin run."""
    spans: list[float] = []
    orig_e, orig_h = suite._eyeq_session, suite._host_session

    def eyeq(*a, **k):  # type: ignore[no-untyped-def]
        tr = orig_e(*a, **k)
        spans.append(tr.end)
        return tr

    def host(*a, **k):  # type: ignore[no-untyped-def]
        tr = orig_h(*a, **k)
        if tr is not None:
            spans.append(tr.end)
        return tr

    suite._eyeq_session, suite._host_session = eyeq, host
    try:
        c0 = time.process_time()
        results = run(Options(dut=dut, builtin=True))
        cpu = time.process_time() - c0
    finally:
        suite._eyeq_session, suite._host_session = orig_e, orig_h
    assert all(r.outcome.verdict in ("pass", "skip") for r in results)
    return cpu, sum(spans)


def baseline(seconds: float) -> float:
    emu = build(sim_config=builtin_eyeq_config(None), keep_rx_times=False)
    c0 = time.process_time()
    emu.run_for(seconds)
    return time.process_time() - c0


def one_mutant(name: str) -> float:
    m = MUTANTS[name]
    c0 = time.process_time()
    run(Options(dut=m.dut, builtin=True, mutant=name))
    return time.process_time() - c0


def summary(values: list[float]) -> str:
    return f"{statistics.median(values):.2f} ({min(values):.2f}..{max(values):.2f})"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-matrix", action="store_true")
    args = ap.parse_args()
    suite_run("eyeq")  # warm the spec caches and layouts once
    for dut in ("eyeq", "host"):
        cpu: list[float] = []
        base: list[float] = []
        ratio: list[float] = []
        virt = 0.0
        for _ in range(args.repeat):
            c, virt = suite_run(dut)
            b = baseline(virt)
            cpu.append(c)
            base.append(b)
            ratio.append(c / b)
        print(f"--dut {dut} --builtin: {summary(cpu)} s CPU for {virt:.1f} s virtual; "
              f"baseline emulator {summary(base)} s; ratio {summary(ratio)}")
    if not args.no_matrix:
        names = sorted(MUTANTS)
        ctx = multiprocessing.get_context("fork")
        w0 = time.perf_counter()
        with ProcessPoolExecutor(max_workers=2, mp_context=ctx) as pool:
            cpus = list(pool.map(one_mutant, names))
        wall = time.perf_counter() - w0
        print(f"mutant matrix ({len(names)} variants, pool of 2): {wall:.1f} s wall; "
              f"sum of CPU {sum(cpus):.1f} s (per variant {summary(cpus)} s); "
              f"wall / summed CPU {wall / sum(cpus):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
