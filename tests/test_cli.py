from __future__ import annotations

import json
import subprocess
import sys

import pytest

from eyeq_spi.cli import main


def test_demo_json_reaches_running_vision(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--virtual-time", "--duration", "4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] and out["state"] == "RUNNING_VISION"
    assert out["elapsed_s"] == pytest.approx(4.0)  # the shared run-summary schema
    msgs = out["messages"]
    assert msgs["HOST_VEH_STATE_MSG"] > 100 and msgs["EYEQ_DIAGNOSTIC_MSG"] > 100
    assert msgs["EYEQ_VIS_OBSTACLES_MSG"] > 20 and out["e2e_errors"] == 0
    assert set(out["link"]) >= {"sequenceErrorCounter", "dataCRCErrorCounter"}


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
