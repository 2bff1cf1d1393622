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
    assert (dlc.ours, dlc.theirs) == (6, 7) and "DLC 6" in dlc.reason
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
    assert "0x738 Obstacle_Status: DLC 6 -> 7" in out and "ours: seed 001 line 1893" in out
    assert "detected: 77 of its 77 IDs" in out
    assert max(len(line) for line in out.splitlines()) <= 80, out
    assert main(["can", "compare", str(public), "--json"]) == 1
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == 7 and {"id", "message", "signal", "field", "ours", "theirs",
                               "reason"} <= set(rows[0])
    me8 = tmp_path / "me8.dbc"
    me8.write_text(dbc_text("me8"), encoding="utf-8")
    assert main(["can", "compare", str(me8), "--protocol", "me8"]) == 0
    assert main(["can", "compare", str(me8)]) == 0  # detected from its IDs
    assert "our me8 DBC (detected: 7 of its 7 IDs)" in capsys.readouterr().out


def vendor_dbc(path: Path) -> Path:
    """Our DBC with Radar_Vel_X in km/h at 0.05 in every obstacle slot and one renamed
    choice in slot 0."""
    db = build_database("extlog2")
    for i in range(13):
        sig = db.get_message_by_frame_id(0x73A + 3 * i).get_signal_by_name("Radar_Vel_X")
        sig.conversion.scale = 0.05
        sig.unit = "km/h"
    db.get_message_by_frame_id(0x739).get_signal_by_name("Obstacle_Valid").choices = {
        1: "New", 2: "Older_valid"}
    db.refresh()
    path.write_text(db.as_dbc_string(), encoding="utf-8")
    return path


def test_each_difference_names_what_differs_once_for_every_slot(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = vendor_dbc(tmp_path / "vendor.dbc")
    capsys.readouterr()
    assert main(["can", "compare", str(path)]) == 1
    out = capsys.readouterr().out
    assert "0x73A..0x75E Obstacle_Data_B_0..12.Radar_Vel_X: scale 0.0625 -> 0.05" in out
    assert "unit m/s -> km/h" in out and "choices {1: New_valid} -> {1: New}" in out
    assert "Radar_Vel_X" in out and len(out.splitlines()) < 12, out
    assert "Obstacle_Lane bits" not in out  # the message's long reading is no reason
    assert main(["can", "compare", str(path), "--json"]) == 1
    rows = json.loads(capsys.readouterr().out)
    scale = next(r for r in rows if r["field"] == "scale")
    assert scale["message"] == "Obstacle_Data_B_0..12" and len(scale["ids"]) == 13
    assert {r["field"] for r in rows} == {"scale", "unit", "choices"}


def test_a_dbc_of_neither_protocol_gets_a_hint(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "other.dbc"
    path.write_text('VERSION ""\n\nBU_:\n\nBO_ 16 Foo: 8 X\n SG_ A : 0|8@1+ (1,0) [0|0] "" X\n')
    capsys.readouterr()
    assert main(["can", "compare", str(path)]) == 2
    err = capsys.readouterr().err
    assert "give --protocol" in err and "extlog2 or me8" in err


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
