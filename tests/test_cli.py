from __future__ import annotations

import json
import subprocess
import sys

import pytest

from eyeq_spi.cli import main


def test_demo_json_reports_an_intact_exchange(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--duration", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] and out["host"]["intact"] and out["eyeq"]["intact"]
    assert out["host"]["sent"] >= 99 and out["eyeq"]["received"] >= 99
    assert out["virtual_s"] == pytest.approx(2.0)


@pytest.mark.parametrize(
    "argv", [[], ["nope"], ["demo", "--duration", "x"], ["demo", "--duration", "-1"]]
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
