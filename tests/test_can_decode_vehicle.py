"""``can decode`` as a car engineer reads it: each log on its own (records, tables, statistics),
times from the log's start, units, values at the signal's resolution; decisions C10 (other
nodes' traffic, the camera's channel) and C11 (lane values at low quality are invalid); a file
that never was its format told from a truncated one."""

from __future__ import annotations

import csv
import json
import random
import struct
from pathlib import Path
from typing import Any

import pytest

can = pytest.importorskip("can", reason="needs the [can] extra (python-can)")
pytest.importorskip("cantools", reason="needs the [can] extra (cantools)")

from eyeq_spi.cli import main  # noqa: E402
from tests import camera_can  # noqa: E402

GAP_S = 1440.0  # the second log starts 24 minutes after the first


def _write(path: Path, messages: list[Any], shift: float = 0.0) -> Path:
    w = can.Logger(str(path))
    for m in messages:
        m.timestamp += shift
        w.on_message_received(m)
    w.stop()
    return path


def _msg(t: float, fid: int, data: bytes, channel: int = 1) -> Any:
    return can.Message(timestamp=t, arbitration_id=fid, data=data, is_extended_id=False,
                       channel=channel)


@pytest.fixture(scope="module")
def two_logs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("two")
    a = _write(d / "a.blf", camera_can.messages(2.0, seed=1))
    b = _write(d / "b.blf", camera_can.messages(2.0, seed=2), shift=GAP_S)
    return a, b


def _json(capsys: pytest.CaptureFixture[str]) -> list[dict[str, Any]]:
    return [json.loads(x) for x in capsys.readouterr().out.splitlines()]


# -- each log on its own -------------------------------------------------------------------

def test_two_logs_give_records_of_each_file(two_logs: tuple[Path, Path],
                                            capsys: pytest.CaptureFixture[str]) -> None:
    a, b = two_logs
    capsys.readouterr()
    assert main(["can", "decode", str(a), str(b), "--channel", "1", "--name", "^Lane$"]) == 0
    human = capsys.readouterr().out.splitlines()
    assert human[0] == f"=== {a}" and f"=== {b}" in human
    assert main(["can", "decode", str(a), str(b), "--json", "--channel", "1"]) == 0
    recs = _json(capsys)
    by_file = {str(a): [r for r in recs if r["file"] == str(a)],
               str(b): [r for r in recs if r["file"] == str(b)]}
    assert len(by_file[str(a)]) + len(by_file[str(b)]) == len(recs)
    for rs in by_file.values():  # frame_index and time count from each file's start
        assert rs[0]["frames"][0] < 10 and 0 <= rs[0]["time"] < 0.01
        assert max(r["time"] for r in rs) < 2.1


def test_two_logs_fill_the_csv_file_column(two_logs: tuple[Path, Path], tmp_path: Path) -> None:
    a, b = two_logs
    assert main(["can", "decode", str(a), str(b), "--csv", str(tmp_path), "--channel",
                 "1"]) == 0
    rows = list(csv.DictReader((tmp_path / "Obstacle_Status.csv").open()))
    assert {r["file"] for r in rows} == {str(a), str(b)}
    first_b = next(r for r in rows if r["file"] == str(b))
    assert int(first_b["frame_index"]) < 50 and float(first_b["time"]) < 0.1


def test_two_logs_give_stats_per_file_and_a_total(two_logs: tuple[Path, Path],
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    a, b = two_logs
    capsys.readouterr()
    assert main(["can", "decode", str(a), str(b), "--stats", "--json"]) == 0
    blocks = _json(capsys)
    assert [x["file"] for x in blocks] == [str(a), str(b), None] and blocks[2]["files"] == 2
    for block in blocks[:2]:
        assert block["duration_s"] < 2.1  # never the 24 minutes between the files
        row = next(r for r in block["ids"] if r["id"] == 0x738)
        assert 75 <= row["median_cycle_ms"] <= 81 and 75 <= row["mean_cycle_ms"] <= 81
    assert blocks[2]["frames"] == blocks[0]["frames"] + blocks[1]["frames"]
    assert main(["can", "decode", str(a), str(b), "--stats"]) == 0
    out = capsys.readouterr().out
    assert f"=== {a}" in out and f"=== {b}" in out and "=== total of 2 files" in out
    assert max(len(line) for line in out.splitlines()) <= 80


# -- units, times, resolution --------------------------------------------------------------

@pytest.fixture(scope="module")
def lane_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Lanes at high quality, then the left lane at quality 0 (C11), 0x669 at -1.88 m."""
    msgs = []
    for k in range(6):
        quality = 3 if k < 3 else 0
        c0 = round(1.875 / 0.00390625)
        a = (1 | quality << 4 | 3 << 6) | c0 << 8 | (0x7FFF + 100) << 24 | 0x7FFF << 40 | 12 << 56
        msgs.append(_msg(100.0 + 0.066 * k, 0x766, a.to_bytes(8, "little")))
        b = (0x7FFF + 5) | round(60 / 0.00390625) << 16 | 1 << 31
        msgs.append(_msg(100.01 + 0.066 * k, 0x767, b.to_bytes(4, "little")))
        left = -94 & 0xFFF  # -1.88 m at 0.02 m
        lane = 3 | 1 << 2 | 1 << 4 | left << 12 | 3 << 40 | 90 << 52
        msgs.append(_msg(100.02 + 0.066 * k, 0x669, lane.to_bytes(8, "little")))
    return _write(tmp_path_factory.mktemp("lanes") / "lanes.log", msgs)


def test_values_have_units_and_the_signal_resolution(lane_log: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["can", "decode", str(lane_log), "--json", "--id", "0x669"]) == 0
    rec = _json(capsys)[0]
    assert rec["fields"]["Distance_To_Left_Lane"] == -1.88  # not -1.8800000000000001
    assert rec["units"]["Distance_To_Left_Lane"] == "m"
    assert main(["can", "decode", str(lane_log), "--id", "0x669"]) == 0
    assert "Distance_To_Left_Lane=-1.88 m" in capsys.readouterr().out
    assert main(["can", "decode", str(lane_log), "--csv", str(tmp_path)]) == 0
    header = (tmp_path / "Lane_AfterMarket.csv").read_text().splitlines()[0].split(",")
    assert "Distance_To_Left_Lane [m]" in header and "Lane_Type_Left" in header


def test_times_are_relative_unless_absolute_is_asked(lane_log: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["can", "decode", str(lane_log), "--json"]) == 0
    times = [r["time"] for r in _json(capsys)]
    assert times[0] == 0.0 and times[1] == 0.01
    assert main(["can", "decode", str(lane_log), "--json", "--absolute-time"]) == 0
    assert _json(capsys)[0]["time"] == pytest.approx(100.0)
    assert main(["can", "decode", str(lane_log)]) == 0
    assert capsys.readouterr().out.split()[1] == "0.000000"


# -- C11: lane values at low quality -------------------------------------------------------

def test_lane_values_at_low_quality_are_invalid_not_errors(
        lane_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["can", "decode", str(lane_log), "--json"]) == 0
    recs = _json(capsys)
    a = [r for r in recs if r["name"] == "LKA_Left_Lane_A"]
    b = [r for r in recs if r["name"] == "LKA_Left_Lane_B"]
    governed = {"Position_Parameter_C0", "Curvature_Parameter_C2",
                "Curvature_Derivative_Parameter_C3", "Width_Left_Marking"}
    assert all(r["invalid"] == [] for r in a[:3])
    assert all(set(r["invalid"]) == governed and r["fields"]["Position_Parameter_C0"] == 1.875
               for r in a[3:])  # shown as sent, flagged
    assert all(r["invalid"] == [] for r in b[:3])  # B takes its lane's latest A quality
    assert all(set(r["invalid"]) == {"Heading_Angle_Parameter_C1", "View_Range"} for r in b[3:])
    assert not any(r["errors"] for r in recs)
    assert main(["can", "decode", str(lane_log), "--csv", str(tmp_path)]) == 0
    rows = list(csv.DictReader((tmp_path / "LKA_Left_Lane_A.csv").open()))
    assert [r["Position_Parameter_C0 [m]"] for r in rows] == ["1.875"] * 3 + [""] * 3
    assert main(["can", "decode", str(lane_log), "--stats", "--json"]) == 0
    stats = _json(capsys)[0]
    by_id = {r["id"]: r for r in stats["ids"]}
    assert by_id[0x766]["invalid"]["Position_Parameter_C0"] == 3
    assert by_id[0x767]["invalid"]["View_Range"] == 3 and stats["error_frames"] == 0


# -- C10: other nodes' traffic and the camera's channel ------------------------------------

@pytest.fixture(scope="module")
def vehicle_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return camera_can.write(tmp_path_factory.mktemp("vehicle") / "vehicle.blf", 3.0).path


def test_a_healthy_vehicle_log_exits_0_without_channel(vehicle_log: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["can", "decode", str(vehicle_log), "--json"]) == 0
    captured = capsys.readouterr()
    recs = [json.loads(x) for x in captured.out.splitlines()]
    assert recs and {r["header"]["channel"] for r in recs} == {"1"}
    assert not any(r["errors"] for r in recs)
    err = " ".join(captured.err.split())  # notes fold to 80 columns
    assert "camera on channel 1" in err and "other nodes' traffic" in err
    assert main(["can", "decode", str(vehicle_log), "--stats", "--json"]) == 0
    stats = _json(capsys)[0]
    assert stats["camera_channel"] == "1" and stats["other_frames"] > 0
    assert {r["channel"] for r in stats["ids"]} == {"1"}


def test_a_channel_that_is_not_a_camera_is_warned_about(
        vehicle_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    main(["can", "decode", str(vehicle_log), "--channel", "0", "--json"])
    err = " ".join(capsys.readouterr().err.split())  # notes fold to 80 columns
    assert "channel 0 does not look like a camera" in err and "0 of the 15" in err
    main(["can", "decode", str(vehicle_log), "--channel", "0", "--stats"])
    err = capsys.readouterr().err
    assert "channel 0 does not look like a camera" in " ".join(err.split())
    assert max(len(line) for line in err.splitlines()) <= 80
    assert main(["can", "decode", str(vehicle_log), "--channel", "1", "--stats"]) == 0
    assert "does not look like" not in capsys.readouterr().err


# -- not the format, or truncated ----------------------------------------------------------

FORMATS = {".blf": "not a BLF log", ".asc": "not an ASC log", ".log": "not a candump log",
           ".trc": "not a TRC log", ".csv": "not a python-can CSV log", ".mf4": "not an MF4 log"}


@pytest.mark.parametrize("suffix", sorted(FORMATS))
def test_random_bytes_are_not_a_log_of_that_format(tmp_path: Path, suffix: str,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / f"random{suffix}"
    path.write_bytes(random.Random(7).randbytes(4096))
    capsys.readouterr()
    assert main(["can", "decode", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and FORMATS[suffix] in err[0] and "truncated" not in err[0], err


@pytest.mark.parametrize("suffix", [".blf", ".asc", ".log", ".trc", ".csv"])
def test_a_real_log_cut_short_is_truncated(tmp_path: Path, suffix: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    whole = camera_can.write(tmp_path / f"whole{suffix}", 2.0).path
    cut = camera_can.truncated_copy(whole, tmp_path / f"cut{suffix}", fraction=0.3)
    capsys.readouterr()
    assert main(["can", "decode", str(cut), "--stats", "--json"]) == 1
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert any("truncated" in line and "frames read" in line for line in err), err
    assert json.loads(captured.out)["frames"] > 0


def test_a_log_cut_in_its_first_line_is_truncated_not_foreign(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "cut.asc"
    path.write_bytes(b"date Wed Nov 25 10:0")
    capsys.readouterr()
    assert main(["can", "decode", str(path)]) == 1
    assert "truncated" in capsys.readouterr().err


def test_a_directory_and_a_bad_id_say_what_they_are(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["can", "decode", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "a directory, not a CAN log" in err and "format ''" not in err
    log = _write(tmp_path / "one.log", [_msg(1.0, 0x650, struct.pack(">ff", 40.0, 10.25))])
    assert main(["can", "decode", str(log), "--id", "foo"]) == 2
    err = capsys.readouterr().err
    assert "invalid CAN ID 'foo'" in err and "lambda" not in err
