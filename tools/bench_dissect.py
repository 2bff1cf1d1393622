#!/usr/bin/env python3
"""Dissector throughput and peak memory on a ~1-million-frame pcapng capture.

The capture repeats a 3 s demo capture (both channels) with shifted timestamps until it holds
``--frames`` transfers; each repetition starts with NUM 0 / RSP 0, which the dissector treats as
a driver reset. Runs ``eyeq-spi dissect --json`` (to /dev/null) and ``--stats`` in subprocesses
and reports frames/s, MB/s and peak RSS.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def build(path: Path, frames: int) -> int:
    from eyeq_spi.capture.pcapng_io import CaptureWriter, read_pcapng

    demo = Path(tempfile.mkdtemp()) / "demo.pcapng"
    subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "demo", "--virtual-time",
                    "--duration", "3", "--capture", str(demo), "--json"], check=True,
                   cwd=ROOT, capture_output=True)
    with open(demo, "rb") as fh:
        recs = list(read_pcapng(fh))
    # start each repetition once Running Vision traffic flows (skip the bring-up)
    recs = recs[len(recs) // 3:]
    period = (recs[-1].time or 0) - (recs[0].time or 0) + 0.01
    n = 0
    with CaptureWriter(path) as w:
        rep = 0
        while n < frames:
            base = rep * period - (recs[0].time or 0)
            for r in recs:
                if n >= frames:
                    break
                w.write(r.direction or "e2h", (r.time or 0) + base, r.data)
                n += 1
            rep += 1
    return n


def measure(args: list[str]) -> tuple[float, int, int]:
    code = ("import resource,sys; from eyeq_spi.cli import main; rc = main(sys.argv[1:]); "
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, rc, file=sys.stderr)")
    t0 = time.perf_counter()
    with open(os.devnull, "w") as null:
        r = subprocess.run([sys.executable, "-c", code, *args], stdout=null,
                           stderr=subprocess.PIPE, text=True, cwd=ROOT)
    dt = time.perf_counter() - t0
    rss, rc = r.stderr.strip().splitlines()[-1].split()
    return dt, int(rss), int(rc)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=1_000_000)
    ap.add_argument("--keep", metavar="FILE", help="keep the generated capture here")
    a = ap.parse_args()
    path = Path(a.keep) if a.keep else Path(tempfile.mkdtemp()) / "big.pcapng"
    t0 = time.perf_counter()
    n = build(path, a.frames)
    size = path.stat().st_size
    out: dict[str, float] = {"frames": n, "file_mb": round(size / 1e6, 1),
                             "build_s": round(time.perf_counter() - t0, 1)}
    for label, extra in (("json", ["--json"]), ("stats", ["--stats"])):
        dt, rss, rc = measure(["dissect", str(path), *extra])
        out[f"{label}_s"] = round(dt, 1)
        out[f"{label}_frames_per_s"] = round(n / dt)
        out[f"{label}_mb_per_s"] = round(size / 1e6 / dt, 2)
        out[f"{label}_peak_rss_mb"] = round(rss / 1024, 1)
        out[f"{label}_exit"] = rc
    print(json.dumps(out, indent=1))
    _ = resource
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
