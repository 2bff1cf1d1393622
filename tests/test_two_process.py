"""Host emulator and simulated EyeQ as two processes over TCP reach Running Vision (bounded)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.realtime
def test_host_and_sim_processes_reach_running_vision_over_tcp(tmp_path: Path) -> None:
    sim = subprocess.Popen(
        [sys.executable, "-m", "eyeq_spi.cli", "sim", "--listen", "tcp://127.0.0.1:0",
         "--duration", "40", "--accept-timeout", "30", "--json"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        assert sim.stdout is not None
        line = sim.stdout.readline().split()
        assert line and line[0] == "LISTEN", (line, sim.stderr.read() if sim.stderr else "")
        host = subprocess.run(
            [sys.executable, "-m", "eyeq_spi.cli", "host", "--port", line[1], "--nvm",
             str(tmp_path / "nvm.json"), "--duration", "30", "--exit-when-running", "--json"],
            cwd=ROOT, capture_output=True, text=True, timeout=60,
        )
    finally:
        sim.terminate()  # SIGTERM ends the sim cleanly, with its summary
        try:
            sim_out, _ = sim.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            sim.kill()
            sim_out, _ = sim.communicate()
    out = json.loads(host.stdout.strip().splitlines()[-1])
    sim_sum = json.loads(sim_out.strip().splitlines()[-1])
    # every time in a summary counts from the start of that process's run, on either side
    assert out["transitions"] and all(0 <= t["t"] <= out["elapsed_s"] for t in out["transitions"])
    assert 0 <= out["running_vision_since"] <= out["elapsed_s"]
    assert sim_sum["interrupted"] is True and sim_sum["connections"] == 1
    assert 0 <= sim_sum["running_vision_since"] <= sim_sum["elapsed_s"], sim_sum
    # demo, host and sim print one schema (README, Run summaries)
    demo = subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "demo", "--virtual-time",
                           "--duration", "1", "--json"], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    demo_sum = json.loads(demo.stdout.strip().splitlines()[-1])
    assert sorted(demo_sum) == sorted(out) == sorted(sim_sum)
    assert demo_sum["scheduling"] is None and out["scheduling"] and sim_sum["scheduling"]
    assert out["state"] == "RUNNING_VISION", host.stderr[-2000:] + host.stdout[-2000:]
    # the exit code and the summary agree; losses, if any, are named (tools/soak_live.py and
    # tests/test_soak_live.py hold the zero-loss bar)
    assert host.returncode == (0 if out["ok"] else 1)
    assert out["ok"] or out["problem"]
    assert out["messages"]["EYEQ_BOOT_STATUS_MSG"] >= 1
    # first ignition with an empty NVM went through the EEPROM read and wrote the NVM
    nvm = json.loads((tmp_path / "nvm.json").read_text())
    assert nvm["intrinsic"]["CCAM_Num_Of_distorParams_m"] == 15
