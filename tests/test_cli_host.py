"""Host emulator and simulated EyeQ as two processes over TCP reach Running Vision (bounded), and
``sim`` reports every host it served."""

from __future__ import annotations

import contextlib
import json
import subprocess
from pathlib import Path

import pytest

from eyeq_spi.summary import KEYS, SESSION_KEYS
from tests.sim_proc import CLI, ROOT, start_sim


def _stop(sim: subprocess.Popen[str]) -> tuple[str, str]:
    sim.terminate()  # SIGTERM ends the sim cleanly, with its summary
    try:
        return sim.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        sim.kill()
        return sim.communicate()


def _host(url: str, nvm: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*CLI, "host", "--port", url, "--nvm", str(nvm), "--duration", "30",
         "--exit-when-running", "--json", *extra],
        cwd=ROOT, capture_output=True, text=True, timeout=90)


@pytest.mark.realtime
def test_host_and_sim_processes_reach_running_vision_over_tcp(tmp_path: Path) -> None:
    sim, url = start_sim("--listen", "tcp://127.0.0.1:0", "--duration", "60",
                         "--accept-timeout", "30", "--json")
    assert url.startswith("tcp://127.0.0.1:")
    try:
        host = _host(url, tmp_path / "nvm.json")
    finally:
        sim_out, _ = _stop(sim)
    out = json.loads(host.stdout.strip().splitlines()[-1])
    # --json: stdout is the summary and nothing else (the address went to stderr), so jq works
    sim_sum = json.loads(sim_out)
    assert sim_sum["address"] == url  # start_sim read it from the LISTEN line on stderr
    # every time in a summary counts from the start of that process's run, on either side
    assert out["transitions"] and all(0 <= t["t"] <= out["elapsed_s"] for t in out["transitions"])
    assert 0 <= out["running_vision_since"] <= out["elapsed_s"]
    assert sim_sum["interrupted"] is True and sim_sum["connections"] == 1
    assert 0 <= sim_sum["running_vision_since"] <= sim_sum["elapsed_s"], sim_sum
    # demo, host and sim print one schema (docs/emulator.md, Run summaries)
    demo = subprocess.run([*CLI, "demo", "--virtual-time", "--duration", "1", "--json"],
                          cwd=ROOT, capture_output=True, text=True, timeout=60)
    demo_sum = json.loads(demo.stdout)
    assert sorted(demo_sum) == sorted(out) == sorted(sim_sum) == sorted(KEYS)
    assert demo_sum["scheduling"] is None and out["scheduling"] and sim_sum["scheduling"]
    assert out["state"] == "RUNNING_VISION", host.stderr[-2000:] + host.stdout[-2000:]
    # the exit code and the summary agree; losses, if any, are named (tools/soak_live.py and
    # tests/test_soak_live.py hold the zero-loss bar)
    assert host.returncode == (0 if out["ok"] else 1)
    assert out["ok"] or out["problem"]
    # what each side received and what it sent, apart: HOST_VEH_STATE is the host's own
    # (--exit-when-running may stop the host before its first one: no count is asserted)
    assert out["received"]["EYEQ_BOOT_STATUS_MSG"] >= 1 and out["sent"]["MESP"] >= 1
    assert "HOST_VEH_STATE_MSG" not in out["received"]
    assert sim_sum["received"]["MESP"] >= 1 and sim_sum["sent"]["EYEQ_BOOT_STATUS_MSG"] >= 1
    assert "HOST_VEH_STATE_MSG" not in sim_sum["sent"]
    assert "EYEQ_BOOT_STATUS_MSG" not in sim_sum["received"]
    # first ignition with an empty NVM went through the EEPROM read and wrote the NVM
    nvm = json.loads((tmp_path / "nvm.json").read_text())
    assert nvm["intrinsic"]["CCAM_Num_Of_distorParams_m"] == 15


@pytest.mark.realtime
def test_sim_reports_each_host_served_and_the_totals(tmp_path: Path) -> None:
    """Two hosts one after the other: two sessions, each with its own counts, and totals that
    are their sums (the last session alone was reported before)."""
    sim, url = start_sim("--listen", "tcp://127.0.0.1:0", "--duration", "90",
                         "--accept-timeout", "30", "--json")
    try:
        hosts = [_host(url, tmp_path / "nvm.json") for _ in range(2)]
    finally:
        sim_out, _ = _stop(sim)
    s = json.loads(sim_out)
    assert s["connections"] == 2 and len(s["sessions"]) == 2, s["sessions"]
    assert all(sorted(sess) == sorted(SESSION_KEYS) for sess in s["sessions"])
    a, b = s["sessions"]
    assert a["ended_s"] <= b["began_s"]
    assert a["received"]["MESP"] >= 1 and b["received"]["MESP"] >= 1
    for name in set(a["received"]) | set(b["received"]):
        assert s["received"][name] == a["received"].get(name, 0) + b["received"].get(name, 0)
    assert s["sent"]["EYEQ_BOOT_STATUS_MSG"] == (a["sent"]["EYEQ_BOOT_STATUS_MSG"]
                                                 + b["sent"]["EYEQ_BOOT_STATUS_MSG"])
    assert s["mesp"]["requests"] == a["mesp"]["requests"] + b["mesp"]["requests"]
    assert s["ok"] == (a["ok"] and b["ok"])
    for h in hosts:
        assert json.loads(h.stdout)["state"] == "RUNNING_VISION", h.stderr[-2000:]


@pytest.mark.realtime
def test_host_reconnect_waits_for_an_eyeq_that_is_not_there_yet(tmp_path: Path) -> None:
    """``host --reconnect`` started before anything listens at its address waits for the EyeQ
    (a sim still starting, a camera powering up) instead of giving up at once."""
    import socket

    with socket.socket() as s:  # a free port; nothing listens on it until the sim starts
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"tcp://127.0.0.1:{port}"
    host = subprocess.Popen([*CLI, "host", "--port", url, "--reconnect", "--exit-when-running",
                             "--duration", "60", "--json", "--nvm", str(tmp_path / "nvm.json")],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sim = None
    try:
        with contextlib.suppress(subprocess.TimeoutExpired):  # up and retrying, no sim yet
            host.wait(timeout=2.0)
        assert host.poll() is None, host.communicate()
        sim, _ = start_sim("--listen", url, "--duration", "60")
        out, err = host.communicate(timeout=90)
        assert host.returncode == 0, err[-2000:]
        assert json.loads(out)["state"] == "RUNNING_VISION"
    finally:
        host.kill()
        if sim is not None:
            _stop(sim)
