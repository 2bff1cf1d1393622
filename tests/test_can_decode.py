"""``can decode`` against logs shaped like a production Mobileye camera's (``tests/camera_can.py``):
decisions C5-C9, ``--channel``, truncated logs, invalid values in every output."""

from __future__ import annotations

import csv
import json
import math
import struct
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

can = pytest.importorskip("can", reason="needs the [can] extra (python-can)")
cantools = pytest.importorskip("cantools", reason="needs the [can] extra (cantools)")

from eyeq_spi.can.dbc import database  # noqa: E402
from eyeq_spi.can.decode import CanDecoder  # noqa: E402
from eyeq_spi.catalog.can import protocol  # noqa: E402
from eyeq_spi.cli import main  # noqa: E402
from tests import camera_can  # noqa: E402

SUFFIXES = (".blf", ".asc", ".log")


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("camera")
    out = {}
    for suffix in (*SUFFIXES, ".trc"):
        path = d / f"camera{suffix}"
        camera_can.write(path, seconds=6.0)
        out[suffix] = path
    return out


def one(fid: int, data: bytes, proto: str = "extlog2") -> dict[str, Any]:
    return CanDecoder(proto).decode(can.Message(arbitration_id=fid, data=data,
                                                is_extended_id=False), 0)


def camera_frame(fid: int) -> bytes:
    import random

    for f, data in camera_can.camera_cycle(3, 0.2, random.Random(1)):
        if f == fid:
            return data
    raise KeyError(fid)


# -- C6-C8, frame by frame (each fails on the reading before these decisions) ----------------

def test_fixed_foe_floats_are_big_endian() -> None:
    rec = one(0x650, struct.pack(">ff", 40.0, 10.25))
    assert rec["fields"] == {"Fixed_Yaw": 40.0, "Fixed_Horizon": 10.25} and not rec["errors"]


def test_0x760_is_car_info_and_obstacles_have_13_slots() -> None:
    rec = one(0x760, camera_frame(0x760))
    assert rec["name"] == "Car_Info" and rec["fields"]["Speed"] == 53 and not rec["errors"]
    a = protocol("extlog2").message("Obstacle_Data_A")
    assert a.slots is not None and a.slots.count == 13
    assert [fid for _, fid, _ in a.instances()][-1] == 0x739 + 3 * 12
    assert one(0x75F, bytes(8))["name"] == "Obstacle_Data_C_12"
    other = one(0x763, bytes(8))  # C10: another node's frame, not an error
    assert other["name"] is None and other["errors"] == []


@pytest.mark.parametrize("fid", camera_can.B_IDS)
def test_short_b_frames_that_hold_every_signal_are_not_errors(fid: int) -> None:
    rec = one(fid, camera_frame(fid))
    assert rec["length"] == 4 and rec["short_dlc"] and rec["errors"] == []
    assert set(rec["fields"]) == {"Heading_Angle_Parameter_C1", "View_Range",
                                  "View_Range_Availability"}
    cut = one(fid, camera_frame(fid)[:3])  # View_Range no longer fits: an error
    assert cut["errors"] == ["DLC 3, spec 8"] and "View_Range" not in cut["fields"]


def test_an_invalid_value_that_is_also_a_normal_state_is_not_invalid() -> None:
    status = one(0x738, camera_frame(0x738))
    assert status["fields"]["Failsafe"] == 0 and "Failsafe" not in status["invalid"]
    obj = one(0x739, camera_frame(0x739))
    assert obj["fields"]["Obstacle_Brake_Lights"] == 0
    assert "Obstacle_Brake_Lights" not in obj["invalid"] and not obj["errors"]


def test_scale_change_invalid_is_0x7fff() -> None:
    young = one(0x73B, struct.pack("<hhhh", 30, 0x7FFF, 0, 0))
    assert "Obstacle_Scale_Change" in young["invalid"] and not young["errors"]
    assert "Obstacle_Scale_Change" not in one(0x73B, struct.pack("<hhhh", 30, 0x7FF, 0, 0))[
        "invalid"]


def test_reference_point_minimum_is_exact() -> None:
    rec = one(0x76A, bytes(8))  # raw 0: (0 - 0x7FFF) / 256 = -127.99609375
    assert rec["fields"]["Ref_Point_2_Position"] == -127.99609375 and rec["errors"] == []


def test_decoder_equals_cantools_on_the_project_dbc(logs: dict[str, Path]) -> None:
    db = database("extlog2")
    dec = CanDecoder("extlog2")
    n = 0
    for i, m in enumerate(can.LogReader(str(logs[".blf"]))):
        if m.channel != camera_can.CAMERA:
            continue
        rec = dec.decode(m, i)
        data = bytes(m.data).ljust(db.get_message_by_frame_id(m.arbitration_id).length, b"\0")
        want = db.decode_message(m.arbitration_id, data, decode_choices=False)
        for k, v in want.items():
            assert math.isclose(rec["fields"][k], v, rel_tol=1e-12, abs_tol=1e-12), (k, rec)
        n += 1
    assert n > 1000


# -- the whole log: clean with --channel (C9), channels listed -------------------------------

@pytest.mark.parametrize("suffix", SUFFIXES)
def test_camera_log_decodes_clean_on_its_channel(logs: dict[str, Path], suffix: str,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    path, ch = str(logs[suffix]), camera_can.camera_channel(suffix)
    capsys.readouterr()
    assert main(["can", "decode", path, "--channel", ch, "--stats", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["error_frames"] == 0 and s["dlc_errors"] == 0 and s["other_ids"] == {}
    assert s["short_dlc"] > 0 and set(s["channels"]) >= {ch}
    by_id = {r["id"]: r for r in s["ids"]}
    assert 75 <= by_id[0x738]["median_cycle_ms"] <= 81  # a deviation, shown, not an error
    assert by_id[0x738]["cycle_deviation_pct"] > 10
    assert by_id[0x669]["median_cycle_ms"] == pytest.approx(80, abs=1.5)
    assert by_id[0x767]["short_dlc"] == by_id[0x767]["frames"]
    assert by_id[0x760]["name"] == "Car_Info"
    assert "Failsafe" not in by_id[0x738]["invalid"]
    # every frame of the channel decodes without an error in the per-frame path too
    assert main(["can", "decode", path, "--channel", ch, "--json"]) == 0
    recs = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert recs and all(r["header"]["channel"] == ch and not r["errors"] for r in recs)
    foe = next(r for r in recs if r["name"] == "Fixed_FOE")["fields"]
    assert foe == {"Fixed_Yaw": 40.0, "Fixed_Horizon": 10.25}


def test_stats_without_channel_lists_channels_and_ids_on_several(
        logs: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    # C10: the radar's 0x650 and the vehicle's 0x773/0x778 are other traffic, not errors
    assert main(["can", "decode", str(logs[".blf"]), "--stats", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert set(s["channels"]) == {"0", "1", "2", "3"}
    assert s["ids_on_several_channels"] == {"0x650": ["1", "2"]}
    assert s["camera_channel"] == "1" and s["error_frames"] == 0
    assert {"0x650", "0x773", "0x778", "0x1A0"} <= set(s["other_ids"])
    assert main(["can", "decode", str(logs[".blf"]), "--stats"]) == 0
    out = capsys.readouterr().out
    assert "0x650 on 1, 2" in out and "camera on channel 1" in out and "--channel 1" in out
    assert "channels (all frames" in out
    assert max(len(line) for line in out.splitlines()) <= 80, out  # several channels: a column more
    assert main(["can", "decode", str(logs[".blf"]), "--channel", "7"]) == 2
    assert "no CAN frames on channel 7 (the channels are: 0, 1, 2, 3)" in \
        capsys.readouterr().err
    assert main(["can", "decode", str(logs[".log"]), "--stats", "--channel", "1"]) == 2
    assert "(the channels are: can0, can1, can2, can3)" in capsys.readouterr().err


# -- truncated logs -------------------------------------------------------------------------

@pytest.mark.parametrize("suffix", [*SUFFIXES, ".trc"])
@pytest.mark.parametrize("stats", [False, True])
def test_a_truncated_log_is_reported_and_exits_1(logs: dict[str, Path], tmp_path: Path,
                                                 suffix: str, stats: bool,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    cut = camera_can.truncated_copy(logs[suffix], tmp_path / f"cut{suffix}")
    ch = camera_can.camera_channel(suffix)
    capsys.readouterr()
    argv = ["can", "decode", str(cut), "--channel", ch, "--json"]
    assert main([*argv, "--stats"] if stats else argv) == 1
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "truncated" in err[0] and "frames read" in err[0], err
    assert captured.out  # what was before the cut is decoded


def test_a_truncated_mf4_is_reported(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("asammdf", reason="MF4 logs need asammdf")
    path = tmp_path / "camera.mf4"
    camera_can.write(path, seconds=2.0)
    assert main(["can", "decode", str(path), "--stats", "--json"]) in (0, 1)
    cut = camera_can.truncated_copy(path, tmp_path / "cut.mf4")
    capsys.readouterr()
    assert main(["can", "decode", str(cut), "--stats"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "truncated" in err[0] and "MF4" in err[0], err



def test_a_cut_or_damaged_mf4_gets_one_line_and_no_library_noise(tmp_path: Path) -> None:
    """asammdf prints tracebacks (its logger, a half-built object's __del__) on such files: the
    user sees only the one error line (a process of its own: asammdf's logger writes to the
    stderr it found at import)."""
    pytest.importorskip("asammdf", reason="MF4 logs need asammdf")
    path = tmp_path / "camera.mf4"
    camera_can.write(path, seconds=2.0)
    data = path.read_bytes()
    cases = [data[:len(data) * tenth // 10] for tenth in range(1, 10)]
    # a damaged block identifier, a damaged link, a damaged byte of compressed frames
    for offset in (data.index(b"##CN") + 2, data.index(b"##CG") + 24, data.index(b"##DZ") + 60):
        cases.append(data[:offset] + bytes([data[offset] ^ 0xFF]) + data[offset + 1:])
    for number, case in enumerate(cases):
        (tmp_path / f"bad{number}.mf4").write_bytes(case)
    script = ("import gc, sys\nfrom eyeq_spi.cli import main\nfor name in sys.argv[1:]:\n"
              "    print(main(['can', 'decode', name, '--stats']), file=sys.stderr)\n"
              "    gc.collect()\n")
    names = [str(tmp_path / f"bad{number}.mf4") for number in range(len(cases))]
    run = subprocess.run([sys.executable, "-c", script, *names], capture_output=True,
                         text=True, timeout=120, check=False)
    err = run.stderr.splitlines()
    assert len(err) == 2 * len(cases) and set(err[1::2]) <= {"1", "2"}, run.stderr


# -- invalid values in the tables and the human statistics --------------------------------

def test_invalid_values_are_empty_in_csv_and_null_in_parquet(
        logs: dict[str, Path], tmp_path: Path) -> None:
    path, ch = str(logs[".blf"]), camera_can.camera_channel(".blf")
    assert main(["can", "decode", path, "--channel", ch, "--csv", str(tmp_path / "c")]) == 0
    rows = list(csv.DictReader((tmp_path / "c" / "Obstacle_Data_B_0.csv").open()))
    assert rows and all(r["Radar_Pos_X [m]"] == "" for r in rows)
    assert all(r["Obstacle_Width [m]"] != "" for r in rows)
    assert main(["can", "decode", path, "--channel", ch, "--raw-invalid", "--csv",
                 str(tmp_path / "r")]) == 0
    rows = list(csv.DictReader((tmp_path / "r" / "Obstacle_Data_B_0.csv").open()))
    assert float(rows[0]["Radar_Pos_X [m]"]) == pytest.approx(0xFFF * 0.0625)
    pq = pytest.importorskip("pyarrow.parquet", reason="--parquet needs pyarrow")
    assert main(["can", "decode", path, "--channel", ch, "--parquet", str(tmp_path / "p")]) == 0
    t = pq.read_table(str(tmp_path / "p" / "Obstacle_Data_B_0.parquet"))
    assert t.column("Radar_Pos_X [m]").null_count == t.num_rows > 0


def test_human_stats_show_dlc_errors_short_dlcs_and_invalid_counts(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "bad.log"
    w = can.Logger(str(path))
    for k, (fid, data) in enumerate([(0x738, bytes(7)), (0x767, bytes(4)), (0x73B, struct.pack(
            "<hhhh", 0, 0x7FFF, 0, 0)), (0x737, bytes([0, 0x80]) + bytes(6))]):
        w.on_message_received(can.Message(timestamp=1.0 + k, arbitration_id=fid, data=data,
                                          is_extended_id=False))
    w.stop()
    capsys.readouterr()
    assert main(["can", "decode", str(path), "--stats"]) == 1
    out = capsys.readouterr().out
    assert "DLC errors 1" in out and "DLC errors x1" in out and "short DLC x1" in out
    assert "Obstacle_Scale_Change invalid x1" in out and "Lane_Curvature invalid x1" in out


def test_stats_with_id_judges_that_id(logs: dict[str, Path],
                                      capsys: pytest.CaptureFixture[str]) -> None:
    path = str(logs[".blf"])
    assert main(["can", "decode", path, "--stats", "--json", "--id", "0x738"]) == 0
    assert main(["can", "decode", path, "--stats", "--json", "--id", "0x773"]) == 0  # C10
    assert main(["can", "decode", path, "--stats", "--json", "--id", "0x773", "--channel",
                 "0"]) == 1


def test_parquet_column_null_in_its_first_row_group_keeps_its_type(
        tmp_path: Path) -> None:
    """A signal invalid (NULL) for the first row group, valid later: its column is a number."""
    pq = pytest.importorskip("pyarrow.parquet", reason="--parquet needs pyarrow")
    path = tmp_path / "late.log"
    w = can.Logger(str(path))
    for k in range(2500):  # Lane_Curvature 8000h (invalid) first, then a value
        raw = 0x8000 if k < 2100 else 50
        w.on_message_received(can.Message(timestamp=1.0 + 0.066 * k, arbitration_id=0x737,
                                          data=struct.pack("<HHHH", raw, 0, 0x7FFF, 0x7FFF),
                                          is_extended_id=False))
    w.stop()
    assert main(["can", "decode", str(path), "--parquet", str(tmp_path / "p")]) == 0
    col = pq.read_table(str(tmp_path / "p" / "Lane.parquet")).column("Lane_Curvature [1/m]")
    assert str(col.type) == "double" and col.null_count == 2100
    assert col[2200].as_py() == pytest.approx(50 * 3.81e-6)


def test_an_asc_without_trigger_block_is_not_truncated(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A converter's ASC (no Begin/End TriggerBlock, as can-utils' log2asc writes) is whole."""
    path = tmp_path / "log2asc.asc"
    path.write_text("date Wed Nov 25 10:00:00 2026\nbase hex  timestamps absolute\n"
                    "no internal events logged\n"
                    "   1.000000 1  650             Rx   d 8 42 20 00 00 41 24 00 00\n")
    capsys.readouterr()
    assert main(["can", "decode", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["fields"]["Fixed_Yaw"] == 40.0
