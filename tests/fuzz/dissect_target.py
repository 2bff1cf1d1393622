"""``eyeq-spi dissect`` on every input format (raw, hex, pcapng), as a subprocess with a time
limit. Inputs are mutations of a small capture of a real bring-up. Oracle: every file ends
with exit code 0, 1 or 2 and at most a one-line error, never an internal error, a traceback or
a hang."""

from __future__ import annotations

import json
import random
import subprocess
import sys
from pathlib import Path

from eyeq_spi.capture.pcapng_io import CaptureWriter
from eyeq_spi.faults.rig import Scene, rig
from eyeq_spi.host.machine import HostState

from .core import FIGURES, Finding, mutate

ROOT = Path(__file__).resolve().parents[2]
FORMATS = ("raw", "hex", "pcapng")
DIRECTIONS = ("h2e", "e2h")


Transfer = tuple[int, float, bytes]  # (direction index, time, bytes)


def seed_log(transfers: int = 300) -> list[Transfer]:
    """The first ``transfers`` transfers of a bring-up to Running Vision."""
    log: list[Transfer] = []
    emu = rig(scene=Scene(1, 1, 1))
    emu.runner.tap = lambda i, t, data: log.append((i, t, data)) if len(log) < transfers \
        else None
    emu.run_for(1.0, stop=lambda: len(log) >= transfers
                and emu.host.state is HostState.RUNNING_VISION)
    return log


def render(fmt: str, log: list[Transfer], path: Path) -> None:
    if fmt == "raw":
        path.write_bytes(b"".join(d for i, _, d in log if i == 1))
    elif fmt == "hex":
        path.write_text("".join(f"{t:.6f} {DIRECTIONS[i % 2]} {d.hex()}\n" for i, t, d in log
                                if d))
    else:
        with CaptureWriter(path) as w:
            for i, t, d in log:
                w.write(DIRECTIONS[i % 2], max(0.0, t), d)


def mutate_log(rng: random.Random, log: list[Transfer]) -> list[Transfer]:
    """Damage at the transfer level: the file stays well-formed, the protocol does not."""
    out = list(log)
    for _ in range(rng.randrange(1, 12)):
        k = rng.randrange(len(out))
        i, t, d = out[k]
        op = rng.randrange(7)
        if op == 0:
            b = bytearray(d)
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
            out[k] = (i, t, bytes(b))
        elif op == 1:
            out[k] = (i, t, d[: rng.randrange(1, len(d) + 1)])
        elif op == 2:
            out.insert(k, out[k])
        elif op == 3:
            del out[k]
        elif op == 4 and k + 1 < len(out):
            out[k], out[k + 1] = out[k + 1], out[k]
        elif op == 5:
            out[k] = (1 - i, t, d)
        else:
            out[k] = (i, t, bytes(rng.randrange(256) for _ in range(len(d))))
        if not out:
            out = list(log)
    return out


def make_inputs(rng: random.Random, log: list[Transfer], out: Path, per_format: int
                ) -> list[tuple[str, Path]]:
    """The seed capture and ``per_format - 1`` mutants in each format (half of them also
    damaged at the byte level)."""
    files = []
    for fmt in FORMATS:
        for n in range(per_format):
            path = out / f"{fmt}-{n}.{fmt}"
            render(fmt, log if n == 0 else mutate_log(rng, log), path)
            if n and n % 2 == 0:
                path.write_bytes(mutate(rng, path.read_bytes()))
            files.append((fmt, path))
    return files


def run_files(files: list[tuple[str, Path]], per_file: float = 10.0
              ) -> list[dict[str, object]]:
    """Dissect each file in one subprocess (the driver), ``per_file`` seconds each at most."""
    cmd = [sys.executable, "-m", "tests.fuzz.dissect_driver", str(per_file),
           *(f"{fmt}:{path}" for fmt, path in files)]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True,
                          timeout=30 + per_file * len(files))
    results = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    if proc.returncode != 0 or len(results) != len(files):
        raise Finding(f"dissect driver died (exit {proc.returncode}): {proc.stderr[-500:]}")
    return results


def check(results: list[dict[str, object]]) -> None:
    for res in results:
        FIGURES["dissect_files"] += 1
        err = str(res["stderr"])
        if res["hang"]:
            raise Finding(f"dissect hung on {res['file']}")
        if res["rc"] not in (0, 1, 2):
            raise Finding(f"dissect exit {res['rc']} on {res['file']}: {err[:300]}")
        if "internal error" in err or "Traceback" in err or len(err.splitlines()) > 1:
            raise Finding(f"dissect on {res['file']}: {err[:300]}")
