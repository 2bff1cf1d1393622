from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from eyeq_spi.cli import main


def test_demo_json_reaches_running_vision(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--virtual-time", "--duration", "4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] and out["state"] == "RUNNING_VISION"
    assert out["elapsed_s"] == pytest.approx(4.0)  # the shared run-summary schema
    rx, tx = out["received"], out["sent"]
    # what the host received and what it sent, apart: HOST_VEH_STATE is the host's own
    assert tx["HOST_VEH_STATE_MSG"] > 100 and "HOST_VEH_STATE_MSG" not in rx
    assert rx["EYEQ_DIAGNOSTIC_MSG"] > 100 and tx["MESP"] > 0
    assert rx["EYEQ_VIS_OBSTACLES_MSG"] > 20 and out["e2e_errors"] == 0
    assert set(out["link"]) >= {"sequenceErrorCounter", "dataCRCErrorCounter"}


def test_demo_keeps_the_nvm_in_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """demo --nvm FILE, as its FATAL_22 note says: the first run learns the calibration from
    the EEPROM and writes it; the next run starts with it (no FATAL_22, no EEPROM read)."""
    nvm = tmp_path / "nvm.json"
    assert main(["demo", "--virtual-time", "--duration", "3", "--nvm", str(nvm), "--json"]) == 0
    first = json.loads(capsys.readouterr().out)
    assert "FATAL_22" in [t["event"] for t in first["transitions"]]
    assert json.loads(nvm.read_text())["ignition_cycles"] == 1
    assert main(["demo", "--virtual-time", "--duration", "3", "--nvm", str(nvm), "--json"]) == 0
    second = json.loads(capsys.readouterr().out)
    assert [t["event"] for t in second["transitions"]] == [
        "BOOT_OK", "PENDING_VISION", "INIT_DONE", "RUNNING_VISION"]
    assert json.loads(nvm.read_text())["ignition_cycles"] == 2


@pytest.mark.parametrize("fn", ["GetEyeQVersions", "GetEyeQExtendedState", "FFSReadFile"])
def test_a_dropped_mesp_reply_is_a_timeout_in_the_summary(
    fn: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """Whenever the reply is dropped: a poll (retried), the EEPROM read, or the versions request
    that the EEPROM-driven reset leaves unanswered (it is asked again after the reset)."""
    assert main(["demo", "--virtual-time", "--duration", "4", "--json", "--drop-reply", fn]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["mesp"]["timeouts"] == 1 and not out["ok"]
    assert "1 MESP timeouts" in out["problem"]
    assert out["versions"] is not None and out["state"] == "RUNNING_VISION"


def test_demo_with_a_corrupt_eeprom_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--virtual-time", "--duration", "3", "--json", "--corrupt-eeprom"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["state"] == "FAILED" and "repair or replace" in out["problem"]


@pytest.mark.parametrize(
    "argv",
    [["nope"], ["demo", "--duration", "x"], ["demo", "--duration", "-1"],
     ["demo", "--objects", "16"], ["demo", "--drop-reply", "GetEyeQVersions:x"],
     ["sim"], ["sim", "--listen", "udp://x:1"], ["host", "--port", "/dev/nonexistent-eyeq"],
     ["demo", "--scenario", "/nonexistent.csv"], ["spec", "show", "nope"]],
)
def test_bad_arguments_exit_2_with_one_line_and_no_traceback(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1 and err.startswith("eyeq-spi:")


def test_console_script_entry_point_runs() -> None:
    r = subprocess.run(
        [sys.executable, "-m", "eyeq_spi.cli", "--version"], capture_output=True, text=True
    )
    assert r.returncode == 0 and "eyeq-spi" in r.stdout
