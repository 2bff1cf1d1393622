"""eyeq-spi dissect: inputs, outputs, filters, stats on known faults, exit codes, bad input."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys
from pathlib import Path

import pytest

from eyeq_spi.capture.pcapng_io import CaptureWriter
from eyeq_spi.cli import main
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.link.frame import FrameCodec, NakReason
from eyeq_spi.transport.segment import segment

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

ROOT = Path(__file__).resolve().parents[1]
FC = FrameCodec()
MC = MessageCodec()


E2E: dict[str, E2EState] = {}


def dasp(name: str, counter: int, stream: str = "default") -> bytes:
    """A DASP message whose rolling counters step like a real sender's (one E2E state per
    stream)."""
    lay = MC.layout(MC.message(name))
    return MC.encode_dasp(name, lay.zero_values(), counter, E2E.setdefault(stream, E2EState()))


class Cap:
    """Builds a capture transfer by transfer, numbering DATA frames per direction."""

    def __init__(self) -> None:
        self.items: list[tuple[str, float, bytes]] = []
        self.num = {"h2e": 0, "e2h": 0}
        self.tid = 0

    def data(self, d: str, t: float, payload: bytes, *, flip: bool = False) -> None:
        wire = bytearray(FC.data_frame(0, self.num[d], payload))
        if flip:
            wire[40] ^= 1
        self.num[d] = (self.num[d] + 1) % 4096
        self.items.append((d, t, bytes(wire)))

    def message(self, d: str, t: float, msg: bytes, *, drop: int | None = None) -> None:
        parts = segment(msg, self.tid)
        if len(parts) > 1:
            self.tid = (self.tid + 1) % 256
        for i, p in enumerate(parts):
            if i == drop:
                self.num[d] += 1  # the frame was lost on the wire
                continue
            self.data(d, t + i * 0.0002, p)

    def raw(self, d: str, t: float, wire: bytes) -> None:
        self.items.append((d, t, wire))

    def pcapng(self, path: Path) -> Path:
        with CaptureWriter(path) as w:
            for d, t, wire in self.items:
                w.write(d, t, wire)
        return path


@pytest.fixture(autouse=True)
def _fresh_e2e() -> None:
    E2E.clear()


@pytest.fixture
def faulty(tmp_path: Path) -> Path:
    c = Cap()
    c.message("e2h", 0.000, dasp("EYEQ_VIS_FAILSAFE_MSG", 0))
    c.message("e2h", 0.0556, dasp("EYEQ_VIS_FAILSAFE_MSG", 1))
    c.message("e2h", 0.1111, dasp("EYEQ_VIS_FAILSAFE_MSG", 3))  # counter gap
    c.message("e2h", 0.15, dasp("EYEQ_VIS_OBSTACLES_MSG", 0), drop=5)  # NUM gap: abort
    c.data("e2h", 0.20, segment(b"\x41" + bytes(116), 0)[0], flip=True)  # CRC error
    c.raw("h2e", 0.201, FC.nak(7, NakReason.CRC_MISMATCH))
    c.raw("h2e", 0.202, FC.ack(8))
    c.raw("e2h", 0.25, bytes(127))  # chip-select fault
    req = MC.mesp.encode_request("GetEyeQVersions", 5, {})
    rep = MC.mesp.encode_reply("GetEyeQVersions", 5, 0, {
        "apiVersionMajor": 9, "apiVersionMinor": 0, "eyeqSwVersionMajor": 9,
        "eyeqSwVersionMinor": 0})
    c.message("h2e", 1.000, req)
    c.message("e2h", 1.002, rep)
    c.message("h2e", 1.100, MC.mesp.encode_request("GetEyeQExtendedState", 6, {}))  # no reply
    c.message("h2e", 2.0, MC.mesp.encode_request("GetEyeQExtendedState", 7, {}))
    c.message("e2h", 2.004, MC.mesp.encode_reply("GetEyeQExtendedState", 7, 0,
                                                 {"mainState": 2, "subState": 0}))
    return c.pcapng(tmp_path / "faulty.pcapng")


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    rc = main(argv)
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_stats_on_known_faults(faulty: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = run(["dissect", str(faulty), "--stats", "--json"], capsys)
    assert rc == 1
    assert len(out.splitlines()) == 1
    s = json.loads(out)
    assert s["kind"] == "stats"
    assert s["crc_errors"] == 1 and s["bad_length"] == 1
    assert s["nak_reasons"] == {"0x002": 1}
    assert s["frames"]["NAK"] == 1 and s["frames"]["ACK"] == 1
    assert s["aborted_transfers"] == {"num_gap": 1}
    assert s["dasp_counter_gaps"] == {"EYEQ_VIS_FAILSAFE_MSG": 1}
    assert s["messages"]["EYEQ_VIS_FAILSAFE_MSG"]["count"] == 3
    assert s["messages"]["EYEQ_VIS_FAILSAFE_MSG"]["mean_hz"] == pytest.approx(18.0, abs=0.05)
    lat = s["mesp_latency"]
    assert lat["GetEyeQVersions"]["count"] == 1
    assert lat["GetEyeQVersions"]["min_ms"] == pytest.approx(2.0, abs=0.01)
    assert lat["GetEyeQExtendedState"]["timeouts"] == 1
    assert lat["GetEyeQExtendedState"]["median_ms"] == pytest.approx(4.0, abs=0.01)


def test_json_lines_contract(faulty: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = run(["dissect", str(faulty), "--json"], capsys)
    assert rc == 1
    rows = [json.loads(line) for line in out.splitlines()]
    frames = [r for r in rows if r["kind"] == "frame"]
    assert [f["index"] for f in frames] == list(range(len(frames)))
    keys = {"kind", "index", "time", "direction", "frame_type", "num", "rsp", "crc_ok",
            "transport", "transfer_id", "nak_reason"}
    assert all(keys <= set(f) for f in frames)
    assert {f["frame_type"] for f in frames} == {"DATA", "ACK", "NAK", "INVALID"}
    msgs = [r for r in rows if r["kind"] == "message"]
    for m in msgs:
        assert {"protocol", "name", "length", "frames", "header", "fields", "errors"} <= set(m)
    mesp = [m for m in msgs if m["protocol"] == "MESP"]
    assert set(mesp[0]["header"]) == {"service", "function", "tag", "counter", "reply"}
    fs = [m for m in msgs if m["name"] == "EYEQ_VIS_FAILSAFE_MSG"]
    assert set(fs[0]["header"]) == {"data_id", "counter"}
    assert "DASP counter gap: expected 2, got 3" in fs[2]["errors"]
    nak = next(f for f in frames if f["frame_type"] == "NAK")
    assert nak["nak_reason"] == 2
    events = [r for r in rows if r["kind"] == "event"]
    assert any(e["type"] == "transfer_aborted" and e["reason"] == "num_gap" for e in events)


def test_clean_capture_exits_0_and_human_view(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    c = Cap()
    for i in range(3):
        c.message("e2h", i / 18, dasp("EYEQ_VIS_FAILSAFE_MSG", i))
    rc, out, _ = run(["dissect", str(c.pcapng(tmp_path / "ok.pcapng"))], capsys)
    assert rc == 0
    assert "DASP EYEQ_VIS_FAILSAFE_MSG" in out and "rainSeverityLevel = 0 (NOT_READY)" in out
    assert "\x1b[" not in out  # colour only on a TTY


def test_human_view_fits_80_columns_and_lines_up(faulty: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Messages alone (``--id``) drop the frame-index column and fit 80 columns; with frames
    shown, a message line's time stands under the frames' times."""
    _, out, _ = run(["dissect", str(faulty), "--id", "0xE5", "--no-tree"], capsys)
    lines = out.splitlines()
    assert len(lines) == 3 and all(len(line.split(" DASP counter gap")[0]) <= 80
                                   for line in lines), lines  # an error may run on
    assert all(line.split()[2:4] == ["DASP", "EYEQ_VIS_FAILSAFE_MSG"] for line in lines)
    _, out, _ = run(["dissect", str(faulty), "--no-tree"], capsys)
    frame = next(line for line in out.splitlines() if " NUM=" in line)
    message = next(line for line in out.splitlines() if " DASP " in line)
    time_end = len(frame.split(" e2h ")[0].split(" h2e ")[0])
    assert message[:time_end].strip() and message[:9].strip() == ""
    assert message[time_end:time_end + 5] in (" e2h ", " h2e ")


def test_filters(faulty: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, out, _ = run(["dissect", str(faulty), "--json", "--protocol", "MESP"], capsys)
    rows = [json.loads(x) for x in out.splitlines()]
    assert rows and all(r["kind"] == "message" and r["protocol"] == "MESP" for r in rows)
    _, out, _ = run(["dissect", str(faulty), "--json", "--id", "0xE5"], capsys)
    rows = [json.loads(x) for x in out.splitlines()]
    assert [r["name"] for r in rows] == ["EYEQ_VIS_FAILSAFE_MSG"] * 3
    _, out, _ = run(["dissect", str(faulty), "--json", "--name", "Versions"], capsys)
    assert {json.loads(x)["name"] for x in out.splitlines()} == {"GetEyeQVersions"}
    _, out, _ = run(["dissect", str(faulty), "--json", "--errors-only"], capsys)
    rows = [json.loads(x) for x in out.splitlines()]
    assert rows and all(
        (r["kind"] == "frame" and (not r["crc_ok"] or r["frame_type"] in ("NAK", "INVALID")))
        or r["kind"] == "event" or (r["kind"] == "message" and r["errors"]) for r in rows)


def test_csv_and_parquet_tables(faulty: Path, tmp_path: Path,
                                capsys: pytest.CaptureFixture[str]) -> None:
    run(["dissect", str(faulty), "--csv", str(tmp_path / "csv")], capsys)
    with open(tmp_path / "csv" / "EYEQ_VIS_FAILSAFE_MSG.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 and "visFailsafes.rainSeverityLevel" in rows[0]
    assert [r["header.counter"] for r in rows] == ["0", "1", "3"]
    run(["dissect", str(faulty), "--parquet", str(tmp_path / "pq")], capsys)
    import pyarrow.parquet as pq

    t = pq.read_table(tmp_path / "pq" / "EYEQ_VIS_FAILSAFE_MSG.parquet")
    assert t.num_rows == 3 and "visFailsafes.crc_16" in t.column_names


def test_raw_and_hex_inputs_and_stdin(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    c = Cap()
    for i in range(4):
        c.message("e2h", i / 18, dasp("EYEQ_VIS_FAILSAFE_MSG", i))
    raw = b"".join(w for _, _, w in c.items)
    (tmp_path / "c.bin").write_bytes(raw)
    hexfile = "\n".join(f"{t:.6f} {d} {w.hex()}" for d, t, w in c.items) + "\n"
    (tmp_path / "c.hex").write_text("# a hex capture\n" + hexfile)
    for path in ("c.bin", "c.hex"):
        rc, out, _ = run(["dissect", str(tmp_path / path), "--json"], capsys)
        rows = [json.loads(x) for x in out.splitlines()]
        assert rc == 0
        assert [r["index"] for r in rows if r["kind"] == "frame"] == list(range(4))
        assert len([r for r in rows if r["kind"] == "message"]) == 4
    hex_rows = [json.loads(x) for x in out.splitlines()]
    assert hex_rows[0]["direction"] == "e2h" and hex_rows[0]["time"] == 0.0
    r = subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "dissect", "-", "--json"],
                       input=raw, capture_output=True, cwd=ROOT)
    assert r.returncode == 0
    assert len([x for x in r.stdout.splitlines() if b'"message"' in x]) == 4


@pytest.mark.parametrize(
    ("content", "msg"),
    [(b"", "empty"), (b"\x00" * 100, "shorter than one"), (b"garbage " * 100, "not an EyeQ"),
     (b"\x0a\x0d\x0d\x0a" + b"\xff" * 50, "malformed pcapng"),
     (b"\xd4\xc3\xb2\xa1" + bytes(60), "classic pcap")],
)
def test_bad_files_give_one_line_and_exit_2(tmp_path: Path, content: bytes, msg: str,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / "bad"
    p.write_bytes(content)
    rc, _, err = run(["dissect", str(p)], capsys)
    assert rc == 2 and msg in err and err.count("\n") == 1 and "Traceback" not in err
    assert f"error: {p}: " in err  # which file: with several, the user must know


def test_truncated_raw_and_pcapng(tmp_path: Path, faulty: Path,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / "t.bin"
    p.write_bytes(FC.data_frame(0, 0, b"\x00\x01x") + bytes(50))
    rc, _, err = run(["dissect", str(p), "--json"], capsys)
    assert rc == 2 and "truncated" in err
    data = faulty.read_bytes()
    (tmp_path / "t.pcapng").write_bytes(data[: len(data) - 77])
    rc, out, err = run(["dissect", str(tmp_path / "t.pcapng"), "--json"], capsys)
    # a pcapng file cut inside a block (a killed writer): read up to its last whole block, one
    # line about the bytes left, exit 1 as for any finding
    assert rc == 1 and "Traceback" not in err and out
    assert "ignored the last" in err and len(err.strip().splitlines()) == 1


def test_missing_file_and_usage_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert run(["dissect", "/nonexistent.pcapng"], capsys)[0] == 2
    assert run(["dissect"], capsys)[0] == 2
    assert run(["dissect", "-", "-"], capsys)[0] == 2


def test_capture_of_wrong_length_transfers_is_kept_as_it_was(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    c = Cap()
    c.raw("h2e", 0.0, bytes(127))
    c.raw("h2e", 0.1, bytes(129))
    c.message("h2e", 0.2, b"\x05\x5e\x05\x03\x01")
    path = c.pcapng(tmp_path / "cs.pcapng")
    rc, out, _ = run(["dissect", str(path), "--json"], capsys)
    rows = [json.loads(x) for x in out.splitlines()]
    frames = [r for r in rows if r["kind"] == "frame"]
    assert [(f["frame_type"], f.get("length")) for f in frames] == [
        ("INVALID", 127), ("INVALID", 129), ("DATA", None)]
    assert rc == 1


def test_demo_capture_round_trip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cap = tmp_path / "demo.pcapng"
    assert main(["demo", "--virtual-time", "--duration", "2", "--capture", str(cap),
                 "--json"]) == 0
    demo = json.loads(capsys.readouterr().out)
    rc, out, _ = run(["dissect", str(cap), "--stats", "--json"], capsys)
    s = json.loads(out.splitlines()[-1])
    assert rc == 0, s
    assert s["messages"]["EYEQ_VIS_OBSTACLES_MSG"]["count"] == \
        demo["received"]["EYEQ_VIS_OBSTACLES_MSG"]
    assert s["messages"]["HOST_VEH_STATE_MSG"]["count"] == demo["sent"]["HOST_VEH_STATE_MSG"]


def test_bounded_memory_on_a_large_capture(tmp_path: Path) -> None:
    """Peak memory of --stats does not grow with the capture: 100k vs 500k frames (the batch
    path's read buffer and chunk arrays are full from about 100k frames on: a smaller capture
    would measure their filling, not growth). One untimed run first, so that both measured runs
    find the catalogue and code caches as a user's second start does."""
    frame = segment(dasp("EYEQ_VIS_FAILSAFE_MSG", 0)[:60], 0)[0]

    def make(n: int) -> Path:
        p = tmp_path / f"big{n}.bin"
        with open(p, "wb") as fh:
            buf = io.BytesIO()
            for i in range(n):
                buf.write(FC.data_frame(0, i % 4096, frame))
                if i % 10000 == 9999:
                    fh.write(buf.getvalue())
                    buf = io.BytesIO()
            fh.write(buf.getvalue())
        return p

    def peak(p: Path) -> int:
        code = ("import resource,sys; from eyeq_spi.cli import main; "
                "rc = main(['dissect', sys.argv[1], '--stats', '--json']); "
                "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)")
        r = subprocess.run([sys.executable, "-c", code, str(p)], capture_output=True, text=True,
                           cwd=ROOT)
        assert r.returncode in (0, 1), r.stderr[-500:]
        return int(r.stderr.strip().splitlines()[-1])

    small_file = make(100_000)
    peak(small_file)
    small, large = peak(small_file), peak(make(500_000))
    assert large < small + 16_384, (small, large)  # KiB: 400k more frames are 51 MB
