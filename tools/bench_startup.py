"""Start-up time of the CLI: ``--help``, ``spec list``, ``spec show``, usage errors, ``dissect``
of a 20-transfer file, and ``dissect --stats`` of a 2 s full-load capture (560 kB: the numpy batch
path, about 4,600 transfers, whose own work is a few ms), each as a fresh process (what a user
waits for).

    python tools/bench_startup.py [--runs N] [--before REV]

Each command runs ``--runs`` times after one warm-up run (which also fills the catalogue cache);
the table gives the median and the spread (min..max) of the wall time, the ratio of the median
to an in-run baseline (``python -c pass`` with the same interpreter: the floor no CLI can beat),
and the median CPU time (user + system), which a loaded machine disturbs less than wall time.
``--before REV`` also runs the commands against ``git archive REV`` of this repository (for example
the commit before a start-up change) in a temporary directory, for a before/after table.

The children run as an installed user's do: with bytecode caches (``.pyc``, written by the warm-up
run into a temporary ``PYTHONPYCACHEPREFIX``, whatever ``PYTHONDONTWRITEBYTECODE`` says here) and
with a filled catalogue cache. ``--no-pyc`` times them compiling every module from source instead.
The load average is printed before and after: on a shared machine, compare rows of one run only.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def commands(small_hex: str, small_pcapng: str, batch: str) -> list[tuple[str, list[str]]]:
    return [
        ("--help", ["--help"]),
        ("spec list", ["spec", "list"]),
        ("spec show EYEQ_VIS_OBSTACLES_MSG", ["spec", "show", "EYEQ_VIS_OBSTACLES_MSG"]),
        ("spec show 0xE4", ["spec", "show", "0xE4"]),
        ("usage error: demo --fatal 999", ["demo", "--fatal", "999"]),
        ("usage error: demo --stop-dasp FOO@3", ["demo", "--stop-dasp", "FOO@3"]),
        ("usage error: host --port socket://x", ["host", "--port", "socket://127.0.0.1"]),
        ("usage error: dissect --id zz", ["dissect", "--id", "zz", small_hex]),
        ("dissect 20 transfers (hex)", ["dissect", small_hex]),
        ("dissect 20 transfers (pcapng) --json", ["dissect", small_pcapng, "--json"]),
        ("dissect --stats, 2 s full load (batch path)", ["dissect", batch, "--stats"]),
    ]


def time_one(argv: list[str], env: dict[str, str], runs: int,
             cwd: Path) -> tuple[list[float], list[float]]:
    """Wall and CPU (user + system) seconds of each run of ``argv`` as a child process, run from
    ``cwd`` (never the repository: ``python -m`` would import the package from there instead of
    from ``PYTHONPATH``)."""
    wall: list[float] = []
    cpu: list[float] = []
    subprocess.run(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   check=False, cwd=cwd)  # warm-up: page cache, .pyc files, catalogue cache
    for _ in range(runs):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        subprocess.run(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                       check=False, cwd=cwd)
        wall.append(time.perf_counter() - t)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return wall, cpu


def make_inputs(tmp: Path) -> tuple[str, str, str]:
    """A 20-transfer hex file and pcapng capture, cut from 1 s of demo traffic, and 2 s of
    full-load traffic."""
    from eyeq_spi.capture.pcapng_io import CaptureWriter, read_pcapng

    batch = tmp / "full2.pcapng"
    subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "demo", "--virtual-time",
                    "--duration", "2", "--objects", "15", "--signs", "20", "--light-spots", "15",
                    "--capture", str(batch)], check=True, cwd=tmp, stdout=subprocess.DEVNULL,
                   env={**os.environ, "PYTHONPATH": str(ROOT)})

    cap = tmp / "demo.pcapng"
    subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "demo", "--virtual-time",
                    "--duration", "1", "--capture", str(cap)], check=False, cwd=tmp,
                   stdout=subprocess.DEVNULL, env={**os.environ, "PYTHONPATH": str(ROOT)})
    with cap.open("rb") as fh:
        recs = [r for _, r in zip(range(20), read_pcapng(fh), strict=False)]
    small_hex = tmp / "small.hex"
    small_hex.write_text("".join(f"{r.time:.6f} {r.direction} {r.data.hex()}\n" for r in recs))
    small_pcapng = tmp / "small.pcapng"
    with CaptureWriter(small_pcapng) as w:
        for r in recs:
            w.write(r.direction or "h2e", r.time or 0.0, r.data)
    return str(small_hex), str(small_pcapng), str(batch)


def trees_to_time(before: str | None, tmp: Path) -> list[tuple[str, Path]]:
    """This checkout ("after"), preceded by git revision ``before`` extracted under ``tmp``."""
    trees = [("after", ROOT)]
    if before:
        old = tmp / "before"
        old.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", before],
                                 check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(old)], input=archive, check=True)
        trees.insert(0, (f"before ({before})", old))
    return trees


def timing_env(tmp: Path) -> dict[str, str]:
    """The environment of a timed run of whole commands: this run's own catalogue cache and
    bytecode under ``tmp`` (warmed by an untimed run), and the references off."""
    env = {**os.environ, "EYEQ_SPI_CACHE_DIR": str(tmp / "cache"),
           "PYTHONPYCACHEPREFIX": str(tmp / "pycache")}
    for key in ("EYEQ_SPI_NO_CACHE", "PYTHONDONTWRITEBYTECODE", "EYEQ_SPI_EXACT"):
        env.pop(key, None)
    return env


def row(label: str, samples: tuple[list[float], list[float]], base: float) -> str:
    wall, cpu = samples
    med = statistics.median(wall)
    lo, hi = min(wall) * 1000, max(wall) * 1000
    return (f"| {label} | {med * 1000:.0f} ms | {lo:.0f}..{hi:.0f} ms | {med / base:.1f}x | "
            f"{statistics.median(cpu) * 1000:.0f} ms | {min(cpu) * 1000:.0f}.."
            f"{max(cpu) * 1000:.0f} ms |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=9)
    ap.add_argument("--before", metavar="REV", help="also time this git revision")
    ap.add_argument("--no-pyc", action="store_true",
                    help="no bytecode cache: every module compiled from source at each start")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        small_hex, small_pcapng, batch = make_inputs(tmp)
        trees = trees_to_time(args.before, tmp)
        base_env = {**os.environ, "EYEQ_SPI_CACHE_DIR": str(tmp / "cache")}
        base_env.pop("EYEQ_SPI_NO_CACHE", None)
        if args.no_pyc:
            base_env["PYTHONDONTWRITEBYTECODE"] = "1"
        else:
            base_env.pop("PYTHONDONTWRITEBYTECODE", None)
            base_env["PYTHONPYCACHEPREFIX"] = str(tmp / "pycache")
        baseline, base_cpu = time_one([sys.executable, "-c", "pass"], base_env, args.runs, tmp)
        base = statistics.median(baseline)
        print(f"baseline python -c pass: median {base * 1000:.0f} ms, "
              f"{min(baseline) * 1000:.0f}..{max(baseline) * 1000:.0f} ms, CPU "
              f"{statistics.median(base_cpu) * 1000:.0f} ms ({args.runs} runs, "
              f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}, {sys.version.split()[0]}, "
              f"{'no bytecode cache' if args.no_pyc else 'with bytecode caches'})")
        # numpy with the BLAS threads the CLI sets (cli.BLAS_THREADS), unless the caller chose
        np_env = {"OPENBLAS_NUM_THREADS": "1", **base_env}
        npw, npc = time_one([sys.executable, "-c", "import numpy"], np_env, args.runs, tmp)
        print(f"baseline python -c 'import numpy' (the floor of a batch-path dissect, one BLAS "
              f"thread as the CLI sets): median "
              f"{statistics.median(npw) * 1000:.0f} ms wall, CPU "
              f"{statistics.median(npc) * 1000:.0f} ms ({min(npc) * 1000:.0f}.."
              f"{max(npc) * 1000:.0f})")
        for name, tree in trees:
            env = {**base_env, "PYTHONPATH": str(tree)}
            print(f"\n{name}: {tree if tree == ROOT else 'git archive'}")
            print("| command | median wall | spread | / baseline | median CPU | CPU spread |\n"
                  "|---|---|---|---|---|---|")
            for label, argv in commands(small_hex, small_pcapng, batch):
                samples = time_one([sys.executable, "-m", "eyeq_spi.cli", *argv], env, args.runs,
                                   tmp)
                print(row(label, samples, base), flush=True)
        print(f"\nload average at the end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
