"""On a real rig of SPI adapters (docs/bench.md), never on the simulated wire.

Run with ``EYEQ_SPI_BENCH=bench.toml`` naming our side (its master and slave channel), and
one of:

- ``EYEQ_SPI_BENCH_PEER=peer.toml``: a second side wired to the first (each master to the
  other's slave): the doctor both ways, the host emulator against the simulated EyeQ, and the
  conformance suite both ways, all on the wires;
- ``EYEQ_SPI_BENCH_EYEQ=1``: the side is wired to a real EyeQ: the host emulator brings it up,
  and the EyeQ suite judges it;
- neither: the side's master wired to its own slave (a loop): the doctor only.

Without ``EYEQ_SPI_BENCH`` every test here is skipped, saying so."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "eyeq_spi.cli"]
BENCH = os.environ.get("EYEQ_SPI_BENCH", "")
PEER = os.environ.get("EYEQ_SPI_BENCH_PEER", "")
EYEQ = os.environ.get("EYEQ_SPI_BENCH_EYEQ", "") == "1"

pytestmark = [
    pytest.mark.hardware,
    pytest.mark.skipif(not BENCH, reason="needs a rig of SPI adapters: set "
                       "EYEQ_SPI_BENCH=bench.toml (docs/bench.md)"),
]


def _cli(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


def test_the_rig_is_fit_for_a_live_eyeq() -> None:
    if EYEQ:
        pytest.skip("the side is wired to an EyeQ, not to a loop or a second side")
    res = _cli("bench", "doctor", BENCH, *(["--peer", PEER] if PEER else []), "--frames",
               "2000", "--json")
    report = json.loads(res.stdout)
    assert res.returncode == 0 and report["fit"], report["reasons"]


@pytest.mark.skipif(not PEER, reason="needs a second side wired to the first: "
                    "EYEQ_SPI_BENCH_PEER=peer.toml")
def test_host_against_the_simulated_eyeq_across_the_wires() -> None:
    sim = subprocess.Popen([*CLI, "sim", "--listen", PEER, "--duration", "40", "--json"],
                           cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        res = _cli("host", "--port", BENCH, "--duration", "30", "--json")
    finally:
        sim.kill()
        sim.communicate()
    out = json.loads(res.stdout)
    assert res.returncode == 0 and out["ok"], out["problem"]
    assert out["spi"]["reply_latency_ms"]["p99_9"] < 10.0


@pytest.mark.skipif(not (PEER or EYEQ), reason="needs an EyeQ on the wires: a second side "
                    "(EYEQ_SPI_BENCH_PEER) or a real one (EYEQ_SPI_BENCH_EYEQ=1)")
def test_the_eyeq_suite_on_the_wires() -> None:
    sim = (subprocess.Popen([*CLI, "sim", "--listen", PEER, "--duration", "200"], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
           if PEER else None)
    try:
        res = _cli("conformance", "--dut", "eyeq", "--port", BENCH)
    finally:
        if sim is not None:
            sim.kill()
            sim.wait()
    assert res.returncode == 0, res.stdout[-4000:]


@pytest.mark.skipif(not PEER, reason="needs a second side wired to the first: "
                    "EYEQ_SPI_BENCH_PEER=peer.toml")
def test_the_host_suite_on_the_wires() -> None:
    host = subprocess.Popen([*CLI, "host", "--port", BENCH, "--duration", "200"], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        res = _cli("conformance", "--dut", "host", "--listen", PEER)
    finally:
        host.kill()
        host.wait()
    assert res.returncode == 0, res.stdout[-4000:]
