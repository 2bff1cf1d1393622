#!/usr/bin/env python3
"""Long fuzz run: every target of ``tests/fuzz`` for a share of ``--budget`` seconds.
In-process targets run coverage-guided under atheris (libFuzzer), one subprocess each; when
atheris is missing they run under the seeded coverage-free mutator of the CI slice. The
``dissect`` target feeds mutated raw/hex/pcapng captures to ``eyeq-spi dissect`` in a subprocess
with a time limit. Prints inputs, frames and messages fuzzed and every finding (libFuzzer
artifacts go to ``--out``). Exit 1 if anything was found.

    python tools/fuzz.py --budget 600 --jobs 2
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import random
import re
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

IN_PROCESS = ("link_rx", "transport_pair", "transport_pair_wire", "decoders", "init_codec",
              "host_messages", "sim_messages", "host_eeprom")
ALL = (*IN_PROCESS, "dissect")


def run_atheris(name: str, seconds: float, out: Path) -> dict[str, Any]:
    figures = out / f"{name}.figures.json"
    cmd = [sys.executable, "-m", "tests.fuzz.atheris_main", name, str(figures),
           f"-max_total_time={max(1, int(seconds))}", "-timeout=30", "-rss_limit_mb=4096",
           f"-artifact_prefix={out}/{name}-", "-print_final_stats=1", "-max_len=2048"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=env,
                          timeout=seconds + 300)
    runs = re.findall(r"stat::number_of_executed_units:\s*(\d+)", proc.stderr)
    done = re.findall(r"Done (\d+) runs", proc.stderr)
    figs = json.loads(figures.read_text()) if figures.exists() else {}
    crashed = proc.returncode != 0
    detail = ""
    if crashed:
        tail = [ln for ln in proc.stderr.splitlines() if ln.strip()][-12:]
        detail = "\n".join(tail)
    return {"target": name, "engine": "atheris", "wall_s": round(time.perf_counter() - t0, 1),
            "execs": int((runs or done or [figs.get("inputs", 0)])[-1]), **figs,
            "findings": 1 if crashed else 0, "detail": detail}


def run_random(name: str, seconds: float, out: Path) -> dict[str, Any]:
    from tests.fuzz.core import FIGURES
    from tests.fuzz.registry import run_slice

    FIGURES.clear()
    t0, seed, inputs, findings = time.perf_counter(), 0, 0, []
    while time.perf_counter() - t0 < seconds:
        res = run_slice(name, 200, seed)
        inputs += res.inputs
        findings += res.findings
        seed += 1
    for i, (_what, data) in enumerate(findings[:20]):
        (out / f"{name}-finding-{i}").write_bytes(data)
    return {"target": name, "engine": "random", "wall_s": round(time.perf_counter() - t0, 1),
            "execs": inputs, **dict(FIGURES), "findings": len(findings),
            "detail": "\n".join(w for w, _ in findings[:5])}


def run_dissect(seconds: float, out: Path) -> dict[str, Any]:
    from tests.fuzz import dissect_target as d
    from tests.fuzz.core import FIGURES, Finding

    FIGURES.clear()
    t0 = time.perf_counter()
    log = d.seed_log()
    rng = random.Random(9)
    files = findings = 0
    detail = []
    work = Path(tempfile.mkdtemp(prefix="dissect-", dir=out))
    while time.perf_counter() - t0 < seconds:
        batch = d.make_inputs(rng, log, work, per_format=10)
        results = d.run_files(batch)
        files += len(results)
        for res in results:
            try:
                d.check([res])
            except Finding as exc:
                findings += 1
                keep = out / f"dissect-finding-{findings}-{Path(str(res['file'])).name}"
                keep.write_bytes(Path(str(res["file"])).read_bytes())
                detail.append(str(exc)[:200])
    return {"target": "dissect", "engine": "subprocess", "execs": files,
            "wall_s": round(time.perf_counter() - t0, 1), "findings": findings,
            "detail": "\n".join(detail[:5])}


def run_one(name: str, engine: str, share: float, out: Path) -> dict[str, Any]:
    if name == "dissect":
        return run_dissect(share, out)
    if engine == "atheris":
        return run_atheris(name, share, out)
    return run_random(name, share, out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=float, required=True, help="seconds in total")
    ap.add_argument("--targets", default=",".join(ALL), help=f"comma list of {', '.join(ALL)}")
    ap.add_argument("--jobs", type=int, default=1, help="targets run side by side")
    ap.add_argument("--engine", choices=("auto", "atheris", "random"), default="auto")
    ap.add_argument("--out", default=None, help="directory for findings (default: a temp dir)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    names = [n for n in args.targets.split(",") if n]
    unknown = set(names) - set(ALL)
    if unknown or args.budget <= 0:
        print(f"fuzz: unknown targets {sorted(unknown)} or bad budget", file=sys.stderr)
        return 2
    engine = args.engine
    if engine == "auto":
        engine = "atheris" if importlib.util.find_spec("atheris") else "random"
        if engine == "random":
            print("fuzz: atheris is not installed (pip install atheris): running the seeded "
                  "coverage-free mutator instead", file=sys.stderr)
    elif engine == "atheris" and not importlib.util.find_spec("atheris"):
        print("fuzz: --engine atheris needs atheris: pip install atheris", file=sys.stderr)
        return 2
    out = Path(args.out or tempfile.mkdtemp(prefix="eyeq-fuzz-"))
    out.mkdir(parents=True, exist_ok=True)
    share = args.budget * max(1, args.jobs) / len(names)
    n = len(names)
    # one process per target: the figures are per process
    with ProcessPoolExecutor(max(1, args.jobs)) as pool:
        results = list(pool.map(run_one, names, [engine] * n, [share] * n, [out] * n))
    total = {k: sum(int(r.get(k, 0)) for r in results)
             for k in ("execs", "frames", "messages", "findings")}
    if args.json:
        print(json.dumps({"budget_s": args.budget, "engine": engine, "out": str(out),
                          "targets": results, "total": total}))
    else:
        for r in results:
            print(f"{r['target']:15s} {r['engine']:10s} {r['execs']:9d} inputs "
                  f"{int(r.get('frames', 0)):10d} frames {int(r.get('messages', 0)):9d} "
                  f"messages  {r['findings']} findings  ({r['wall_s']} s)")
            if r["detail"]:
                print("    " + r["detail"].replace("\n", "\n    "))
        print(f"total: {total['execs']} inputs, {total['frames']} frames, "
              f"{total['messages']} messages, {total['findings']} findings; artifacts in {out}")
    return 1 if total["findings"] else 0


if __name__ == "__main__":
    sys.exit(main())
