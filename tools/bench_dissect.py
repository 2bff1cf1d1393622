#!/usr/bin/env python3
"""Dissector throughput, before (exact engine) and after (batch path), with in-run baselines.

Input: a full-load demo capture (``demo --virtual-time --objects 15 --signs 20 --light-spots 15
--capture``, ``--duration`` seconds), as pcapng and as raw (the EyeQ -> host channel). Measures,
``--repeat`` times each, median and spread (min..max):

- batch frame validation (header fields + CRC verdict of every frame,
  ``engine_fast_frames.validate``);
- the in-run baselines over the same frames: a Python loop of ``binascii.crc_hqx`` and a loop of
  ``struct.unpack_from`` of the frame layout (header word, CRC);
- ``eyeq-spi dissect --stats`` / ``--json`` / ``--parquet`` as subprocesses: "after" reads the
  file (batch path); "before" reads the same bytes from a pipe, which cannot seek and so takes the
  exact engine; frames/s, ratio after/before, ratio to the crc_hqx baseline, peak RSS.

Every figure is frames per CPU-second (user + system time of the process doing the work; for the
CLI runs the whole ``eyeq-spi`` process as a user starts it, from start-up to exit, from the
kernel's account of that child), so that neighbours on a loaded machine do not skew it.

``--split``: ``dissect --stats`` start-up and steady state apart, from whole-process CPU times of
three full-load captures (``--short`` 2 s, ``--capture`` 60 s, ``--long`` 600 s by default, made
if not given). Run ``i`` of each capture makes one estimate: steady state = (frames long - frames
short) / (CPU long - CPU short), start-up = CPU short - frames short / steady state; the whole
process on the 60 s and on the long capture in frames/s. Each is given as median (min..max) over
``--repeat`` runs and as a ratio to an in-run baseline: start-up to ``python -c "import numpy"``
(the floor of any batch run), steady state and the whole process to the ``crc_hqx`` loop.

The CLI runs start as an installed copy does: with the package's bytecode cached (pip compiles it
at install; a checkout writes ``__pycache__`` on its first run). Where ``PYTHONDONTWRITEBYTECODE``
is set, as in some sandboxes, every run would compile the package's 370 kB of sources again
(0.065 CPU-s); the children then keep their bytecode under ``--keep``/pycache
(``PYTHONPYCACHEPREFIX``) after one untimed run. ``--cold-bytecode`` keeps the inherited
environment instead (and says so in the output).

    python tools/bench_dissect.py [--duration 30] [--repeat 3] [--keep DIR] [--capture FILE]
                                  [--cold-bytecode] [--split [--short FILE] [--long FILE]]
"""

from __future__ import annotations

import argparse
import binascii
import importlib.util
import json
import os
import resource
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GOALS = {"validate": 3_000_000, "stats": 250_000, "parquet": 150_000, "json": 60_000,
         "startup_cpu_s": 0.15, "steady": 1_000_000}


def build(dirpath: Path, duration: float, name: str = "full.pcapng") -> Path:
    cap = dirpath / name
    subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "demo", "--virtual-time",
                    "--duration", str(duration), "--objects", "15", "--signs", "20",
                    "--light-spots", "15", "--capture", str(cap), "--json"], check=True,
                   cwd=ROOT, capture_output=True)
    return cap


def timed(fn: Callable[[], object], repeat: int) -> list[float]:
    """CPU seconds of each of ``repeat`` calls."""
    out = []
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        out.append(time.process_time() - t0)
    return out


def summary(n: int, times: list[float]) -> dict[str, float]:
    rates = sorted(n / t for t in times)
    return {"median": round(statistics.median(rates)), "min": round(rates[0]),
            "max": round(rates[-1])}


ENV: dict[str, str] | None = None  # the children's environment (None: inherited)


def cli(args: list[str], stdin: Path | None) -> tuple[float, int]:
    """CPU seconds (user + system) and peak RSS (kB) of one ``eyeq-spi`` process, as a user runs
    it (``python -m eyeq_spi.cli``: the console entry, exit included), from the kernel's account
    of that child alone (``os.wait4``): on a loaded machine wall time measures the neighbours."""
    cmd = [sys.executable, "-m", "eyeq_spi.cli", *args]
    with open(os.devnull, "w") as null, tempfile.TemporaryFile() as err:
        cat = None if stdin is None else subprocess.Popen(["cat", str(stdin)],
                                                           stdout=subprocess.PIPE)
        proc = subprocess.Popen(cmd, stdin=None if cat is None else cat.stdout, stdout=null,
                                stderr=err, cwd=ROOT, env=ENV)
        if cat is not None and cat.stdout is not None:
            cat.stdout.close()  # the child holds the pipe now
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)  # waited: Popen must not wait again
        if cat is not None:
            cat.wait()
        if proc.returncode not in (0, 1):
            err.seek(0)
            raise SystemExit(f"dissect failed: {err.read()[-500:].decode(errors='replace')}")
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss


def frames_of(cap: Path) -> int:
    from eyeq_spi.capture.pcapng_fast import pcapng_chunks

    with open(cap, "rb") as fh:
        return sum(len(c) for c in pcapng_chunks(fh))


def python_cpu(code: str, repeat: int) -> list[float]:
    """CPU seconds (user + system) of ``python -c code`` as a child, each of ``repeat`` runs,
    with numpy's BLAS threads as the CLI sets them (``cli.BLAS_THREADS``, unless the caller's
    environment chose), so that ``import numpy`` is the floor of a batch run."""
    from eyeq_spi.cli import BLAS_THREADS

    env = {BLAS_THREADS[0]: BLAS_THREADS[1], **(os.environ if ENV is None else ENV)}
    out = []
    for _ in range(repeat):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([sys.executable, "-c", code], check=True, env=env)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        out.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return out


def spread(values: list[float], nd: int = 3) -> dict[str, float]:
    v = sorted(values)
    return {"median": round(statistics.median(v), nd), "min": round(v[0], nd),
            "max": round(v[-1], nd)}


def split(a: argparse.Namespace, work: Path, base_crc: dict[str, float]) -> dict[str, object]:
    """``dissect --stats`` start-up and steady state apart (module docstring, ``--split``)."""
    short = a.short or build(work, 2, "short.pcapng")
    mid = a.capture or build(work, 60, "full60.pcapng")
    long = a.long or build(work, 600, "full600.pcapng")
    n = {k: frames_of(p) for k, p in (("short", short), ("mid", mid), ("long", long))}
    for p in (short, mid, long):  # untimed: page cache, bytecode, catalogue and code caches
        cli(["dissect", str(p), "--stats"], None)
    numpy_cpu = python_cpu("import numpy", a.repeat)
    bare_cpu = python_cpu("pass", a.repeat)
    startup, steady, whole, whole_long = [], [], [], []
    for _ in range(a.repeat):
        cs = cli(["dissect", str(short), "--stats"], None)[0]
        cm = cli(["dissect", str(mid), "--stats"], None)[0]
        cl = cli(["dissect", str(long), "--stats"], None)[0]
        rate = (n["long"] - n["short"]) / (cl - cs)
        steady.append(rate)
        startup.append(cs - n["short"] / rate)
        whole.append(n["mid"] / cm)
        whole_long.append(n["long"] / cl)
    crc = base_crc["median"]
    return {
        "frames": n,
        "baseline_python_pass_cpu_s": spread(bare_cpu),
        "baseline_import_numpy_cpu_s": spread(numpy_cpu),
        "startup_cpu_s": {**spread(startup), "x_import_numpy": round(
            statistics.median(startup) / statistics.median(numpy_cpu), 2),
            "goal": GOALS["startup_cpu_s"]},
        "steady_frames_per_s": {**spread(steady, 0), "x_crc_hqx": round(
            statistics.median(steady) / crc, 3), "goal": GOALS["steady"]},
        "whole_process_capture_frames_per_s": {**spread(whole, 0), "x_crc_hqx": round(
            statistics.median(whole) / crc, 3), "goal": GOALS["stats"]},
        "whole_process_long_frames_per_s": {**spread(whole_long, 0), "x_crc_hqx": round(
            statistics.median(whole_long) / crc, 3)},
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--capture", type=Path, help="use this pcapng instead of a new demo capture")
    ap.add_argument("--keep", type=Path, help="write the captures and tables here")
    ap.add_argument("--skip-before", action="store_true", help="do not time the exact path")
    ap.add_argument("--no-cli", action="store_true", help="baselines and validation only")
    ap.add_argument("--split", action="store_true",
                    help="dissect --stats start-up and steady state apart (see above)")
    ap.add_argument("--short", type=Path, help="--split: the short capture (default: 2 s made)")
    ap.add_argument("--long", type=Path, help="--split: the long capture (default: 600 s made)")
    ap.add_argument("--cold-bytecode", action="store_true",
                    help="CLI children in the inherited environment, even if it forbids "
                    "writing bytecode (each run then compiles the package's sources)")
    a = ap.parse_args()
    work = a.keep or Path(tempfile.mkdtemp())
    work.mkdir(parents=True, exist_ok=True)
    for name in ("capture", "short", "long"):  # the children run in the repository
        if getattr(a, name) is not None:
            setattr(a, name, getattr(a, name).resolve())
    if a.split and not a.capture:
        a.capture = build(work, 60, "full60.pcapng")
    cap = a.capture or build(work, a.duration)

    import numpy as np

    from eyeq_spi.capture.pcapng_fast import pcapng_chunks
    from eyeq_spi.dissect.engine_fast_frames import validate
    from eyeq_spi.link.frame import FrameCodec

    with open(cap, "rb") as fh:
        chunks = list(pcapng_chunks(fh, 1 << 30))
    data = np.concatenate([c.data for c in chunks])
    n = len(data)
    raw = work / "e2h.bin"
    e2h = np.concatenate([c.data[c.direction == 1] for c in chunks])
    raw.write_bytes(e2h.tobytes())
    frames = [bytes(r) for r in data]
    codec = FrameCodec()
    hdr = struct.Struct("<IH")

    def crc_loop() -> None:
        for f in frames:
            binascii.crc_hqx(f[:4] + f[6:], 0xFFFF)

    def unpack_loop() -> None:
        for f in frames:
            hdr.unpack_from(f, 0)

    out: dict[str, object] = {"frames": n, "pcapng_mb": round(cap.stat().st_size / 1e6, 1),
                              "raw_frames": len(e2h)}
    base_crc = summary(n, timed(crc_loop, a.repeat))
    base_unpack = summary(n, timed(unpack_loop, a.repeat))
    whole = chunks[0]
    valid = summary(n, timed(lambda: validate(whole.data, whole.length, codec), a.repeat))
    out["baseline_crc_hqx_loop"] = base_crc
    out["baseline_struct_unpack_loop"] = base_unpack
    out["batch_validation"] = {**valid, "x_crc_hqx": round(valid["median"] / base_crc["median"], 2),
                               "x_struct": round(valid["median"] / base_unpack["median"], 2),
                               "goal": GOALS["validate"]}
    global ENV
    if os.environ.get("PYTHONDONTWRITEBYTECODE") and not a.cold_bytecode:
        ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        ENV["PYTHONPYCACHEPREFIX"] = str((work / "pycache").resolve())
        warms = [["--stats"], ["--json"], ["--parquet", str(work / "tables")]]
        for warm in warms[:2 if importlib.util.find_spec("pyarrow") is None else 3]:  # untimed
            if not a.split:
                cli(["dissect", str(raw), "--direction", "e2h", *warm], None)
        out["bytecode"] = f"cached in {ENV['PYTHONPYCACHEPREFIX']}"
    else:
        out["bytecode"] = ("compiled at every start (PYTHONDONTWRITEBYTECODE)"
                           if os.environ.get("PYTHONDONTWRITEBYTECODE") else "as inherited")
    out["load_average"] = round(os.getloadavg()[0], 1)
    if "EYEQ_SPI_CACHE_DIR" not in os.environ:  # a cache of this run's own, found as a user's
        # is (platformdirs' XDG rule: that lookup is part of every start)
        ENV = {**(ENV or os.environ), "XDG_CACHE_HOME": str((work / "cache").resolve())}
    if a.split:
        out["split"] = split(a, work, base_crc)
        print(json.dumps(out, indent=1))
        return 0
    modes = {"stats": ["--stats"], "json": ["--json"],
             "parquet": ["--parquet", str(work / "tables")]}
    if importlib.util.find_spec("pyarrow") is None:  # the [parquet] extra is not installed
        del modes["parquet"]
        out["parquet"] = "skipped: needs pyarrow (python -m pip install -e '.[test]')"
    for fmt, path, count, extra in () if a.no_cli else (
            ("pcapng", cap, n, []), ("raw", raw, len(e2h), ["--direction", "e2h"])):
        for mode, args in modes.items():
            argv = ["dissect", "-", *extra, *args]
            row: dict[str, object] = {}
            for label, stdin in (("after", None), ("before", path)):
                if label == "before" and a.skip_before:
                    continue
                runs = [cli(argv if stdin else [*argv[:1], str(path), *argv[2:]], stdin)
                        for _ in range(a.repeat if label == "after" else 1)]
                row[label] = {**summary(count, [r[0] for r in runs]),
                              "peak_rss_mb": round(max(r[1] for r in runs) / 1024, 1)}
            after = row["after"]["median"]  # type: ignore[index]
            if "before" in row:
                row["x_before"] = round(after / row["before"]["median"], 1)  # type: ignore[index]
            row["x_crc_hqx"] = round(after / base_crc["median"], 3)
            row["goal"] = GOALS[mode]
            out[f"{mode}_{fmt}"] = row
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
