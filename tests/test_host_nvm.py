"""NVM file (atomic writes) and scenario sources."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from eyeq_spi.cli import main
from eyeq_spi.errors import InputError, OutputError
from eyeq_spi.host.nvm import Nvm, alignment_defaults
from eyeq_spi.host.scenario import ConstantDrive, CsvScenario


def test_round_trip_and_first_power_up(tmp_path: Path) -> None:
    nvm = Nvm(tmp_path / "n.json")
    assert nvm.load().intrinsic == {} and nvm.load_problem is None  # missing file: first power-up
    nvm.data.intrinsic = {"CCAM_camK1_FocalLengthX_m": 1502.5625}
    stored = {"horizonKA": 1.0, "yawKA": -2.0, "rollAngleKA": 0.01, "cameraAlignmentValidKA": 1.0}
    nvm.data.alignment = dict(stored)
    nvm.save()
    again = Nvm(tmp_path / "n.json").load()
    assert again.intrinsic == {"CCAM_camK1_FocalLengthX_m": 1502.5625}
    assert again.alignment == stored


def test_a_crash_during_save_leaves_the_old_file_and_no_debris(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "n.json"
    nvm = Nvm(path)
    nvm.data.ignition_cycles = 1
    nvm.save()
    before = path.read_bytes()

    def crash(*args: object) -> None:
        raise OSError("power lost")

    monkeypatch.setattr(os, "replace", crash)
    nvm.data.ignition_cycles = 2
    with pytest.raises(OutputError):
        nvm.save()
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["n.json"]


def test_corrupt_file_is_reported_and_treated_as_empty(tmp_path: Path) -> None:
    path = tmp_path / "n.json"
    path.write_text("{not json")
    nvm = Nvm(path)
    assert nvm.load().intrinsic == {}
    assert nvm.load_problem and "unreadable NVM" in nvm.load_problem
    path.write_text(json.dumps({"alignment": {"bogus": 1}}))
    assert Nvm(path).load().alignment == alignment_defaults()  # a name §21 lacks is ignored
    for bad in ("NaN", '"x"', "true", "1e999"):
        path.write_text('{"alignment": {"yawKA": ' + bad + '}}')
        nvm = Nvm(path)
        assert nvm.load().alignment == alignment_defaults(), bad
        assert nvm.load_problem and "yawKA" in nvm.load_problem, bad


def test_csv_scenario_errors_are_typed(tmp_path: Path) -> None:
    bad = tmp_path / "bad.csv"
    for text, msg in (("speed\n1\n", "'time'"), ("time,vehicleVelocity\n0,x\n", ":2:"),
                      ("time,vehicleVelocity\n1,2\n0,3\n", "backwards"),
                      ("time,vehicleVelocity\n", "no data rows"),
                      ("time,vehicleVelocity\n0,1,2\n", "3 fields"),
                      ("time,vehicleVelocity\n0,nan\n", "finite")):
        bad.write_text(text)
        with pytest.raises(InputError, match=msg):
            CsvScenario(bad)
    with pytest.raises(InputError):
        CsvScenario(tmp_path / "missing.csv")
    with pytest.raises(InputError):
        CsvScenario(_write(tmp_path, "time,noSuchSignal\n0,1\n"), allowed={"vehicleVelocity"})
    with pytest.raises(InputError):
        ConstantDrive(float("inf"))


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.csv"
    p.write_text(text)
    return p


def test_csv_scenario_holds_values(tmp_path: Path) -> None:
    s = CsvScenario(_write(tmp_path, "time,vehicleVelocity,vehicleYawRate\n0,10,0\n2,20,0.1\n"))
    assert s.signals(1.9) == {"vehicleVelocity": 10.0, "vehicleYawRate": 0.0}
    assert s.signals(2.0)["vehicleVelocity"] == 20.0 and s.signals(99)["vehicleYawRate"] == 0.1


def test_bad_scenario_on_the_cli_is_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                           ) -> None:
    assert main(["demo", "--virtual-time", "--scenario",
                 str(_write(tmp_path, "nope\n"))]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "'time'" in err
