"""``eyeq-spi can dbc`` / ``can decode`` and ``demo --can-out``: outputs like ``dissect`` (human,
JSON Lines, CSV, Parquet, stats), bad input as one line and exit 2, never a traceback."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

can = pytest.importorskip("can", reason="needs the [can] extra (python-can)")
cantools = pytest.importorskip("cantools", reason="needs the [can] extra (cantools)")

from eyeq_spi.cli import main  # noqa: E402


@pytest.fixture(scope="module")
def demo_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("can") / "demo.asc"
    rc = main(["demo", "--virtual-time", "--duration", "1.6", "--objects", "4", "--json",
               "--can-out", str(path), "--can-protocol", "extlog2"])
    assert rc == 0
    return path


def test_dbc_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["can", "dbc", "--output", str(tmp_path)]) == 0
    assert {p.name for p in tmp_path.iterdir()} == {"extlog2.dbc", "me8.dbc"}
    db = cantools.database.load_file(str(tmp_path / "me8.dbc"))
    assert db.get_message_by_frame_id(0x703).get_signal_by_name("Yaw_Rate").byte_order == \
        "big_endian"
    capsys.readouterr()
    assert main(["can", "dbc", "--protocol", "extlog2", "--output", "-"]) == 0
    text = capsys.readouterr().out
    assert "BO_ 1849 Obstacle_Data_A_0: 8 EyeQ_Gateway" in text  # 0x739
    assert 'BA_ "GenMsgCycleTime" BO_ 1848 66;' in text  # 0x738 at 66 ms (C3)
    assert main(["can", "dbc", "--output", "-"]) == 2


def test_decode_human_json_and_stats(demo_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["can", "decode", str(demo_log)]) == 0
    human = capsys.readouterr().out.splitlines()
    assert any("0x737 Lane" in line and "Lane_Curvature=" in line for line in human)
    assert main(["can", "decode", str(demo_log), "--json", "--id", "0x739"]) == 0
    recs = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert recs and all(r["kind"] == "message" and r["protocol"] == "CAN" for r in recs)
    assert {r["name"] for r in recs} == {"Obstacle_Data_A_0"}
    assert set(recs[0]["fields"]) >= {"Obstacle_Pos_X", "Obstacle_Type"}
    assert recs[0]["labels"]["Obstacle_Type"] in ("Vehicle", "Truck", "Bike", "Ped", "Bicycle")
    assert main(["can", "decode", str(demo_log), "--stats", "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert stats["kind"] == "stats" and stats["other_ids"] == {}
    by_id = {r["id"]: r for r in stats["ids"]}
    assert by_id[0x738]["median_cycle_ms"] == pytest.approx(66.0, abs=0.01)
    assert by_id[0x669]["cycle_deviation_pct"] == pytest.approx(0.0, abs=0.01)
    assert by_id[0x73A]["invalid"]["Radar_Pos_X"] == by_id[0x73A]["frames"]  # no radar
    assert main(["can", "decode", str(demo_log), "--stats"]) == 0
    text = capsys.readouterr().out
    assert "Obstacle_Status" in text
    assert max(len(line) for line in text.splitlines()) <= 80, text  # an 80-column terminal


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_decode_tables(demo_log: Path, tmp_path: Path, fmt: str) -> None:
    if fmt == "parquet":
        pytest.importorskip("pyarrow", reason="--parquet needs pyarrow")
    out = tmp_path / fmt
    assert main(["can", "decode", str(demo_log), f"--{fmt}", str(out)]) == 0
    files = {p.stem for p in out.iterdir()}
    assert {"Lane", "Obstacle_Status", "Obstacle_Data_A_0"} <= files
    if fmt == "csv":
        header = (out / "Lane.csv").read_text().splitlines()[0].split(",")
        assert {"file", "frame_index", "time", "header.id", "Lane_Curvature [1/m]"} <= \
            set(header)
    else:
        import pyarrow.parquet as pq

        t = pq.read_table(str(out / "Lane.parquet"))
        assert t.num_rows > 10 and "Lane_Curvature [1/m]" in t.column_names


def test_decode_reports_wrong_dlc_and_out_of_range_and_other_ids_apart(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "bad.log"
    w = can.Logger(str(path))
    w.on_message_received(can.Message(timestamp=1.0, arbitration_id=0x123, data=b"\x00",
                                      is_extended_id=False))
    w.on_message_received(can.Message(timestamp=1.1, arbitration_id=0x738, data=bytes(7),
                                      is_extended_id=False))  # the v2.32 DBC's DLC
    # Obstacle_Length raw 0x70 = 56 m > 31 m
    w.on_message_received(can.Message(timestamp=1.2, arbitration_id=0x73A,
                                      data=bytes([0x70, 20, 5, 0xF0, 0xFF, 0, 0x08, 0x7F]),
                                      is_extended_id=False))
    w.stop()
    capsys.readouterr()
    assert main(["can", "decode", str(path), "--json"]) == 1
    recs = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    # C10: 0x123 is another node's frame: counted apart (stderr, --stats), not a record
    assert [r["header"]["id"] for r in recs] == [0x738, 0x73A]
    assert [r["frames"] for r in recs] == [[1], [2]]
    assert recs[0]["errors"] == ["DLC 7, spec 6"]
    assert any("Obstacle_Length" in e for e in recs[1]["errors"])
    assert set(recs[1]["invalid"]) >= {"Radar_Pos_X", "Radar_Vel_X", "Matched_Radar_ID"}
    assert main(["can", "decode", str(path), "--stats", "--json"]) == 1
    stats = json.loads(capsys.readouterr().out)
    assert stats["other_ids"] == {"0x123": 1} and stats["out_of_range_values"] == 1
    assert stats["error_frames"] == 2


@pytest.mark.parametrize(("argv", "needle"), [
    (["can", "decode", "/nonexistent/x.blf"], "no such file"),
    (["can", "decode", "x.xyz"], "unknown CAN log format"),
    (["can", "decode", "GARBAGE.blf"], "not a BLF log"),
    (["can", "decode", "."], "a directory, not a CAN log"),
    (["can", "decode", "EMPTY.asc", "--id", "foo"], "invalid CAN ID 'foo'"),
    (["can", "decode", "EMPTY.asc"], "no CAN frames"),
    (["demo", "--virtual-time", "--duration", "0.1", "--can-out", "out.xyz"], "suffixes"),
    (["demo", "--virtual-time", "--duration", "0.1", "--can-out", "nosuchif:x"], "CAN bus"),
    (["sim", "--pty", "--can-out", "virtual"], "not to sim"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                          monkeypatch: pytest.MonkeyPatch, argv: list[str],
                                          needle: str) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "GARBAGE.blf").write_bytes(b"this is not a BLF file at all" * 10)
    (tmp_path / "EMPTY.asc").write_text("")
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0] and "Traceback" not in err[0], err
