"""``export --vcd``: the size is said before writing and bounded by --vcd-max-size; idle time
can be compressed; the long export shows the shared progress bar (tests/test_cli_progress.py)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest

from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.cli import main
from eyeq_spi.logic.options import SpiOptions
from eyeq_spi.logic.vcd import read_vcd
from eyeq_spi.logic.vcd_write import estimate_size, write_vcd

pytestmark = pytest.mark.twin  # runs a reference/fast twin: also run with EYEQ_SPI_EXACT=1


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("vcdsize") / "demo.pcapng"
    assert main(["demo", "--virtual-time", "--duration", "1", "--capture", str(path),
                 "--json"]) == 0
    return path


def test_the_size_is_said_first_and_close(demo: Path, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    out = tmp_path / "d.vcd"
    assert main(["export", str(demo), "--vcd", str(out), "--json"]) == 0
    err = capsys.readouterr().err
    said = float(err.split("will be about ")[1].split(" MB")[0].replace(",", ""))
    real = out.stat().st_size / 1e6
    assert said == pytest.approx(real, rel=0.15), (said, real)


def test_a_vcd_over_the_limit_is_refused_before_writing(demo: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]
                                                        ) -> None:
    out = tmp_path / "big.vcd"
    assert main(["export", str(demo), "--vcd", str(out), "--vcd-max-size", "1"]) == 2
    err = capsys.readouterr().err
    assert "would be about" in err and "--vcd-max-size" in err and not out.exists()


def test_idle_time_is_compressed_and_said() -> None:
    recs = [Transfer(0.001, "h2e", bytes(range(128))), Transfer(2.0, "e2h", bytes(128)),
            Transfer(2.0002, "h2e", b"\x55" * 128)]
    plain, short = io.StringIO(), io.StringIO()
    write_vcd(recs, plain)
    write_vcd(recs, short, max_idle=150e-6)  # the 2 s gap is cut, the 0.1 ms one kept
    back = list(read_vcd(io.BytesIO(short.getvalue().encode()), SpiOptions()))
    assert [(r.direction, r.data) for r in back] == [(r.direction, r.data) for r in recs]
    times = [r.time for r in back]
    assert times[1] - times[0] < 0.001 and times[2] - times[1] == pytest.approx(0.0002, abs=2e-6)
    assert "idle time compressed" in short.getvalue() and len(short.getvalue()) < len(
        plain.getvalue())


def test_estimate_grows_with_bits_not_with_time() -> None:
    one = estimate_size(100, 12_800, 1.0)
    assert estimate_size(100, 12_800, 1000.0) < 1.25 * one < estimate_size(200, 25_600, 1.0)


def test_export_json_still_reports(demo: Path, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "j.vcd"
    assert main(["export", str(demo), "--vcd", str(out), "--vcd-max-idle", "0.0001",
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["vcd"]["transfers"] == summary["transfers"] > 0
