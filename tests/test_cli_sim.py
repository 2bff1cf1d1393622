"""`eyeq-spi sim` over a socket is one simulated EyeQ that every new connection powers up (boot
status first; ``--boot-fail N`` counts boots across connections), and Switch EyeQ Application
while its boot failed boots it again, as the reset line does in virtual time. `eyeq-spi host
--reconnect` (no reset line) reaches Running Vision against ``sim --boot-fail 1``. Bounded
cross-process test: generous timeouts, no timing figure asserted."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.sim_proc import start_sim

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "eyeq_spi.cli"]
LIGHT = ["--objects", "1", "--signs", "1", "--light-spots", "1"]


def _summary(stdout: str) -> dict[str, Any]:
    return dict(json.loads(stdout.strip().splitlines()[-1]))


@pytest.mark.realtime
def test_host_reconnect_reaches_vision_against_a_failing_boot_and_each_connection_boots(
        tmp_path: Path) -> None:
    sim, url = start_sim("--listen", "tcp://127.0.0.1:0", "--boot-fail", "1",
                         "--duration", "120", "--accept-timeout", "60", "--json", *LIGHT)
    try:
        hosts = []
        for k in range(2):
            res = subprocess.run(
                [*CLI, "host", "--port", url, "--reconnect", "--duration", "40",
                 "--exit-when-running", "--json", "--nvm", str(tmp_path / "nvm.json")],
                cwd=ROOT, capture_output=True, text=True, timeout=90)
            assert res.returncode == 0, (k, res.stdout[-2000:], res.stderr[-2000:])
            hosts.append(_summary(res.stdout))
        sim.send_signal(signal.SIGTERM)
        out, _ = sim.communicate(timeout=30)
    finally:
        if sim.poll() is None:
            sim.kill()
            sim.wait(timeout=10)
    first, second = hosts
    # the first boot failed: the host soft-reset the EyeQ, which booted again
    assert first["running_vision_since"] is not None and first["eyeq_resets"] >= 1, first
    assert first["boot"]["TestResults"] == 0
    # the second connection is a power-up too: a boot status first, and this one boots well
    assert second["running_vision_since"] is not None and second["boot"]["TestResults"] == 0
    summary = _summary(out)
    assert summary["connections"] == 2
    assert summary["boot"]["boots"] == 3, summary  # failed, rebooted, second connection
