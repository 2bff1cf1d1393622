"""``eyeq-spi can compare OTHER.dbc``: a vendor's DBC against ours, signal by signal, with our
reasons; tried on a generated "public-style" DBC with the known public mistakes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

cantools = pytest.importorskip("cantools", reason="needs the [can] extra (cantools)")

from eyeq_spi.can.compare import compare  # noqa: E402
from eyeq_spi.can.dbc import build_database, dbc_text  # noqa: E402
from eyeq_spi.cli import main  # noqa: E402


def public_style_dbc(path: Path) -> Path:
    """Our DBC with the mistakes public ExtLogData2 DBCs make: 0x738 DLC 7, the pitch scale
    20% off, the close-car bit read as part of a 13-bit Failsafe, curvature 4e-6."""
    from cantools.database.can import Signal

    db = build_database("extlog2")
    status = db.get_message_by_frame_id(0x738)
    status.length = 7
    status.signals.remove(status.get_signal_by_name("Failsafe"))
    status.signals.remove(status.get_signal_by_name("Close_Car"))
    status.signals.append(Signal(name="FailSafe", start=40, length=13))
    lane = db.get_message_by_frame_id(0x737)
    lane.get_signal_by_name("Lane_Curvature").conversion.scale = 4e-6
    lane.get_signal_by_name("Pitch_Angle").conversion.scale *= 1.2
    db.refresh()
    path.write_text(db.as_dbc_string(), encoding="utf-8")
    return path


def test_public_style_dbc_differences_and_reasons(tmp_path: Path) -> None:
    diffs = compare(str(public_style_dbc(tmp_path / "public.dbc")), "extlog2")
    got = {(d.message, d.signal, d.field): d for d in diffs}
    assert set(got) == {
        ("Obstacle_Status", None, "dlc"), ("Obstacle_Status", "Failsafe", "start"),
        ("Obstacle_Status", "Failsafe", "length"), ("Obstacle_Status", "Failsafe", "overlap"),
        ("Obstacle_Status", "Close_Car", "missing"), ("Lane", "Lane_Curvature", "scale"),
        ("Lane", "Pitch_Angle", "scale")}, sorted(got)
    dlc = got[("Obstacle_Status", None, "dlc")]
    assert (dlc.ours, dlc.theirs) == (6, 7) and "DLC 6" in dlc.reason and "C1" in dlc.reason
    assert "Close_Car" in got[("Obstacle_Status", "Failsafe", "overlap")].theirs
    assert "line 1971" in got[("Obstacle_Status", "Failsafe", "overlap")].reason
    assert "+20.0% off" in got[("Lane", "Pitch_Angle", "scale")].reason
    curv = got[("Lane", "Lane_Curvature", "scale")]
    assert (curv.ours, curv.theirs) == (3.81e-6, 4e-6) and "as printed" in curv.reason


def test_compare_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    same = tmp_path / "ours.dbc"
    same.write_text(dbc_text("extlog2"), encoding="utf-8")
    capsys.readouterr()
    assert main(["can", "compare", str(same)]) == 0
    assert "the same as our extlog2 DBC" in capsys.readouterr().out
    public = public_style_dbc(tmp_path / "public.dbc")
    assert main(["can", "compare", str(public)]) == 1
    out = capsys.readouterr().out
    assert "0x738 Obstacle_Status: dlc: ours 6, theirs 7" in out and "our reason:" in out
    assert main(["can", "compare", str(public), "--json"]) == 1
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == 7 and {"id", "message", "signal", "field", "ours", "theirs",
                               "reason"} <= set(rows[0])
    me8 = tmp_path / "me8.dbc"
    me8.write_text(dbc_text("me8"), encoding="utf-8")
    assert main(["can", "compare", str(me8), "--protocol", "me8"]) == 0


@pytest.mark.parametrize(("content", "needle"), [(None, "no such file"),
                                                 ("BO_ broken {{{", "not a readable DBC")])
def test_compare_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                       content: str | None, needle: str) -> None:
    path = tmp_path / "x.dbc"
    if content is not None:
        path.write_text(content)
    capsys.readouterr()
    assert main(["can", "compare", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err
