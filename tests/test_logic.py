"""Bench tools: logic-analyzer inputs of dissect, VCD export, MDF4/MCAP exports,
replay into the host emulator and to a port."""

from __future__ import annotations

import io
import json
import threading
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eyeq_spi.capture.pcapng_io import CaptureWriter, Transfer, read_pcapng
from eyeq_spi.cli import main
from eyeq_spi.errors import InputError
from eyeq_spi.io.plain import detect, open_transfers
from eyeq_spi.link.frame import FrameCodec
from eyeq_spi.logic.options import SpiOptions
from eyeq_spi.logic.vcd import read_vcd
from eyeq_spi.logic.vcd_write import write_vcd

pytestmark = pytest.mark.twin  # runs a reference/fast twin: also run with EYEQ_SPI_EXACT=1


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def _jsonl(text: str) -> list[dict[str, Any]]:
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def _per_direction(records: list[dict[str, Any]]) -> dict[tuple[str, str], list[Any]]:
    """Frames, messages and events of each direction without times, global indices and file (the
    interleaving of the two channels may differ by a transfer's duration)."""
    out: dict[tuple[str, str], list[Any]] = {}
    for r in records:
        body = {k: v for k, v in r.items() if k not in ("time", "index", "frames", "file")}
        out.setdefault((r["direction"], r["kind"]), []).append(body)
    return out


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """0.8 s of the emulator (Fatal 22, EEPROM reset, Running Vision at 0.53 s) as pcapng."""
    path = tmp_path_factory.mktemp("bench") / "demo.pcapng"
    rc = main(["demo", "--virtual-time", "--duration", "0.8", "--capture", str(path), "--json"])
    assert rc == 0
    return path


@pytest.fixture(scope="module")
def demo_records(demo: Path) -> list[Transfer]:
    with demo.open("rb") as fh:
        return list(read_pcapng(fh))


@pytest.fixture(scope="module")
def demo_json(demo: Path) -> list[dict[str, Any]]:
    import contextlib

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        main(["dissect", str(demo), "--json"])
    return _jsonl(buf.getvalue())


# -- VCD ----------------------------------------------------------------------------------
def test_vcd_export_round_trips_through_dissect(demo: Path, demo_json: list[dict[str, Any]],
                                                tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    vcd = tmp_path / "demo.vcd"
    rc, out, _ = _run(capsys, "export", str(demo), "--vcd", str(vcd), "--json")
    assert rc == 0 and json.loads(out)["vcd"]["transfers"] == sum(
        r["kind"] == "frame" for r in demo_json)
    rc, out, _ = _run(capsys, "dissect", str(vcd), "--json")  # detected as vcd
    got = _jsonl(out)
    assert rc == 0 and _per_direction(got) == _per_direction(demo_json)
    # timestamps come from the capture: equal, or moved by at most one transfer (102.4 µs)
    # where an ACK and a DATA frame of one channel were handed over at the same instant
    frames_a = sorted((r["direction"], r["time"]) for r in demo_json if r["kind"] == "frame")
    frames_b = sorted((r["direction"], r["time"]) for r in got if r["kind"] == "frame")
    lag = [b[1] - a[1] for a, b in zip(frames_a, frames_b, strict=True)]
    assert min(lag) > -1e-9 and max(lag) < 110e-6
    assert sum(abs(x) < 1e-9 for x in lag) > 0.9 * len(lag)


def test_vcd_signals_and_timing(tmp_path: Path) -> None:
    """10 MHz, mode 1: clock idles low, data set on the rising edge, 128 bytes in 102.4 µs."""
    buf = io.StringIO()
    write_vcd([Transfer(0.001, "e2h", b"\xa5" + bytes(127))], buf)
    text = buf.getvalue()
    assert "$timescale 10ns $end" in text and "e2h_mosi" in text and "h2e_cs" in text
    body = text.split("$enddefinitions $end")[1]
    assert "#100000\n0e\n#100005\n1g\n1f\n" in body  # CS falls; MOSI=1 with CLK rising
    assert "#110245\n1e" in body  # CS rises after 1024 bits of 100 ns and half a period


transfers = st.lists(st.tuples(st.sampled_from(["h2e", "e2h"]),
                               st.binary(min_size=0, max_size=140)), min_size=1, max_size=6)


@given(transfers, st.sampled_from([0, 1, 2, 3]), st.sampled_from(["msb_first", "lsb_first"]))
def test_vcd_writer_and_reader_agree_in_every_mode(items: list[tuple[str, bytes]], mode: int,
                                                   order: str) -> None:
    opts = SpiOptions(mode=mode, bit_order=order)
    recs = [Transfer(None if i % 2 else i * 1e-3, d, data) for i, (d, data) in enumerate(items)]
    buf = io.StringIO()
    write_vcd(recs, buf, opts)
    got = list(read_vcd(io.BytesIO(buf.getvalue().encode()), opts))
    for d in ("h2e", "e2h"):
        assert [r.data for r in got if r.direction == d] == \
            [r.data for r in recs if r.direction == d]


@given(transfers, st.sampled_from([0, 1, 3]), st.sampled_from(["msb_first", "lsb_first"]),
       st.integers(min_value=7, max_value=4000), st.data())
def test_vcd_reads_alike_in_any_chunks(items: list[tuple[str, bytes]], mode: int,
                                       order: str, chunk: int, data: st.DataObject) -> None:
    """Any waveform, cut anywhere (a chip select that rises in the middle of a byte too), gives
    the same transfers whatever the reader's chunk size."""
    opts = SpiOptions(mode=mode, bit_order=order)
    recs = [Transfer(i * 1e-3, d, payload) for i, (d, payload) in enumerate(items)]
    buf = io.StringIO()
    write_vcd(recs, buf, opts)
    text = buf.getvalue()
    lines = text.split("\n")
    body = lines.index("$end", lines.index("$dumpvars")) + 1
    for _ in range(data.draw(st.integers(min_value=0, max_value=3))):
        # chip select edges at random places: transfers cut in the middle of a byte
        at = data.draw(st.integers(min_value=body, max_value=len(lines) - 1))
        lines.insert(at, data.draw(st.sampled_from(["1a", "0a", "1e", "0e"])))
    text = "\n".join(lines)
    raw = text.encode()
    small = list(read_vcd(io.BytesIO(raw), opts, chunk_size=chunk))
    assert small == list(read_vcd(io.BytesIO(raw), opts))


def test_chip_select_fault_is_a_wrong_length_transfer(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    frames = FrameCodec()
    good = frames.data_frame(0, 0, bytes([0, 4]) + b"\x5e\x01\x5e\x02" + bytes(116))
    path = tmp_path / "cs.vcd"
    with path.open("w") as fh:
        write_vcd([Transfer(0.0, "h2e", good), Transfer(0.001, "h2e", good[:77])], fh)
    _, out, _ = _run(capsys, "dissect", str(path), "--json", "--format", "vcd")
    frames_out = [r for r in _jsonl(out) if r["kind"] == "frame"]
    assert frames_out[0]["frame_type"] == "DATA" and frames_out[0]["crc_ok"]
    assert frames_out[1]["frame_type"] == "INVALID" and frames_out[1]["length"] == 77
    assert frames_out[1]["time"] == pytest.approx(0.001)


def test_vcd_with_other_signal_names(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A PulseView export names channels D0..D3: --signals maps them, --channel-map or the
    channel's name gives the direction."""
    buf = io.StringIO()
    write_vcd([Transfer(0.0, "h2e", b"\x01\x02\x03")], buf)
    text = buf.getvalue()
    for sig, new in (("h2e_cs", "D0"), ("h2e_clk", "D1"), ("h2e_mosi", "D2"),
                     ("h2e_miso", "D3")):
        text = text.replace(f" {sig} ", f" {new} ")
    path = tmp_path / "pv.vcd"
    path.write_text(text)
    rc, out, _ = _run(capsys, "dissect", str(path), "--json")  # only e2h_* is found: idle
    assert rc == 0 and out == ""
    rc, out, err = _run(capsys, "dissect", str(path), "--json", "--signals", "bus=D0,D1,D2,D3",
                        "--channel-map", "e2h=bus")
    assert rc == 1, err  # a 3-byte transfer is a protocol error (L8)
    frames_out = [r for r in _jsonl(out) if r["kind"] == "frame"]
    assert [(r["direction"], r["length"]) for r in frames_out] == [("e2h", 3)]


# -- Saleae ---------------------------------------------------------------------------------
def _saleae2(records: list[Transfer], names: dict[str, str]) -> str:
    lines = ['name,type,start_time,duration,"mosi","miso"']
    lines.append(f'"{names["h2e"]}","result",0.0,8e-07,0x11,0xFF')  # cut by the capture start
    for r in records:
        name = names[r.direction or "h2e"]
        t = r.time or 0.0
        lines.append(f'"{name}","enable",{t!r},2e-08,,')
        for i, b in enumerate(r.data):
            lines.append(f'"{name}","result",{t + 1e-6 + i * 8e-7!r},8e-07,0x{b:02X},0xFF')
        lines.append(f'"{name}","disable",{t + 1.1e-4!r},2e-08,,')
    return "\n".join(lines) + "\n"


def test_saleae2_export_reads_like_the_capture(demo_records: list[Transfer],
                                               demo_json: list[dict[str, Any]], tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "logic2.csv"
    path.write_text(_saleae2(demo_records, {"h2e": "SPI h2e", "e2h": "SPI e2h"}))
    rc, out, err = _run(capsys, "dissect", str(path), "--json")
    assert rc == 0, err
    got = _jsonl(out)
    assert _per_direction(got) == _per_direction(demo_json)
    assert [r["time"] for r in got if r["kind"] == "frame"] == \
        [r.time for r in demo_records]
    # analyzers with other names need the map
    path.write_text(_saleae2(demo_records[:20], {"h2e": "SPI [1]", "e2h": "SPI [2]"}))
    rc, _, err = _run(capsys, "dissect", str(path), "--json")
    assert rc == 2 and "--channel-map" in err and err.count("\n") == 1
    rc, out, err = _run(capsys, "dissect", str(path), "--json",
                        "--channel-map", "h2e=SPI [1]:mosi,e2h=SPI [2]")
    assert rc in (0, 1), err
    assert Counter(r["direction"] for r in _jsonl(out) if r["kind"] == "frame") == \
        Counter(r.direction for r in demo_records[:20])


def test_saleae1_export_with_packet_ids(demo_records: list[Transfer], tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    recs = [r for r in demo_records if r.direction == "e2h"][:40]
    lines = ["Time [s],Packet ID,MOSI,MISO"]
    for pid, r in enumerate(recs):
        t = r.time or 0.0
        lines += [f"{t + i * 8e-7:.9f},{pid},0x{b:02X},0x00" for i, b in enumerate(r.data)]
    path = tmp_path / "logic1.csv"
    path.write_text("\n".join(lines) + "\n")
    assert detect(path.read_bytes()[:4096]) == "saleae1"
    rc, out, err = _run(capsys, "dissect", str(path), "--json", "--direction", "e2h")
    assert rc in (0, 1), err
    frames_out = [r for r in _jsonl(out) if r["kind"] == "frame"]
    assert len(frames_out) == 40 and {r["direction"] for r in frames_out} == {"e2h"}
    assert all(r["crc_ok"] for r in frames_out)
    # a full-duplex single bus: MISO carries the other direction
    rc, out, _ = _run(capsys, "dissect", str(path), "--json",
                      "--channel-map", "e2h=:mosi,h2e=:miso")
    assert Counter(r["direction"] for r in _jsonl(out) if r["kind"] == "frame") == \
        {"e2h": 40, "h2e": 40}


@pytest.mark.parametrize(("content", "fmt", "msg"), [
    (b'name,type,start_time,duration,"mosi","miso"\n"SPI h2e","result",0.1,1e-6,0x01,0x00\n',
     None, "no Enable"),
    (b'name,type,start_time,duration,"mosi","miso"\n"h2e","enable",0.1,1e-6,,\n'
     b'"h2e","result",0.1,1e-6,\'A\',0x00\n', None, "not a byte"),
    (b'name,type,start_time,duration,"mosi","miso"\n"h2e","glitch",0.1,1e-6,,\n', None,
     "row type"),
    (b"Time [s],Packet ID,MOSI,MISO\n0.1,,0x01,0x02\n", None, "no Packet ID"),
    (b"$timescale 1ns $end\n$var wire 1 ! h2e_cs $end\n", None, "truncated VCD"),
    (b"$timescale 3ns $end\n$enddefinitions $end\n", None, "timescale"),
    (b"$timescale 1ns $end\n$var wire 1 ! foo $end\n$enddefinitions $end\n#0\n1!\n", None,
     "no SPI signals"),
    (b"$timescale 1ns $end\n$var wire 1 ! h2e_clk $end\n$var wire 1 \" h2e_mosi $end\n"
     b"$enddefinitions $end\n", None, "no cs signal"),
    (b"hello,world\n", "saleae2", "not a Saleae Logic 2"),
])
def test_bad_logic_captures_give_one_line_and_exit_2(
        tmp_path: Path, content: bytes, fmt: str | None, msg: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "bad"
    path.write_bytes(content)
    rc, _, err = _run(capsys, "dissect", str(path), *(["--format", fmt] if fmt else []))
    assert rc == 2 and msg in err and err.count("\n") == 1, err


_VCD_HEAD = ("$timescale 1ns $end\n$var wire 1 a h2e_cs $end\n$var wire 1 b h2e_clk $end\n"
             "$var wire 1 c h2e_mosi $end\n$enddefinitions $end\n")


@given(st.sampled_from(["saleae2", "saleae1", "vcd"]),
       st.one_of(st.binary(max_size=300),
                 st.lists(st.sampled_from(["#1", "#x", "0a", "1a", "0b", "1b", "1c", "xa", "b1 a",
                                           "r1.5 c", "$comment", "$end", "$dumpvars", "#99",
                                           "2a", "", "\r"]), max_size=60)
                 .map(lambda toks: (_VCD_HEAD + "\n".join(toks)).encode()),
                 st.lists(st.sampled_from(['"h2e","enable",0.1,1e-6,,', '"h2e","result",0.2,'
                                           '1e-6,0x08,0x00', '"h2e","disable",0.3,1e-6,,',
                                           '"e2h","result",x,1,0x1FF,', "0.1,1,0x08,0x00",
                                           "0.1,,0x08,", "a,b", '"', ""]), max_size=30)
                 .map(lambda rows: ('name,type,start_time,duration,"mosi","miso"\n'
                                    + "\n".join(rows)).encode())))
def test_logic_readers_raise_only_input_errors(fmt: str, data: bytes) -> None:
    """Any bytes in any logic format: records or one InputError, never another exception."""
    try:
        for rec in open_transfers(io.BytesIO(data), fmt)[1]:
            assert isinstance(rec.data, bytes) and len(rec.data) <= 4096
    except InputError:
        pass


def test_vcd_reading_memory_is_bounded() -> None:
    """A chip select that never rises does not grow a transfer without limit."""
    head = b"$timescale 1ns $end\n$var wire 1 a cs $end\n$var wire 1 b clk $end\n" \
           b"$var wire 1 c mosi $end\n$enddefinitions $end\n#0\n0a\n"
    body = b"".join(b"#%d\n1b\n#%d\n0b\n" % (2 * i + 1, 2 * i + 2) for i in range(8 * 4200))
    with pytest.raises(InputError, match="longer than"):
        list(open_transfers(io.BytesIO(head + body))[1])


# -- MDF4 and MCAP ----------------------------------------------------------------------------
def test_mdf_export_reads_back_with_asammdf(demo: Path, demo_json: list[dict[str, Any]],
                                            tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    asammdf = pytest.importorskip("asammdf", reason="the [export] extra is not installed")
    out_path = tmp_path / "demo.mf4"
    rc, _, err = _run(capsys, "export", str(demo), "--mdf", str(out_path))
    assert rc == 0, err
    mdf = asammdf.MDF(str(out_path))
    try:
        groups = {g.channel_group.acq_name: i for i, g in enumerate(mdf.groups)}
        msgs = [r for r in demo_json if r["kind"] == "message" and r["fields"]]
        for name in {r["name"] for r in msgs}:
            assert any(k.startswith(f"{name} ") for k in groups), name
        obst = [r for r in msgs if r["name"] == "EYEQ_VIS_OBSTACLES_MSG"]
        gi = groups["EYEQ_VIS_OBSTACLES_MSG e2h"]
        sig = mdf.get("visObjects.visObs[0].physicalState.width", group=gi)
        assert list(sig.timestamps) == pytest.approx([r["time"] for r in obst])
        assert list(sig.samples) == pytest.approx(
            [r["fields"]["visObjects"]["visObs"][0]["physicalState"]["width"] for r in obst])
        assert sig.unit == "meter"  # the seed's unit text
        # an enum as a value-to-text conversion
        diag = groups["EYEQ_DIAGNOSTIC_MSG e2h"]
        state = mdf.get("Main_State", group=diag, raw=False)
        raw = mdf.get("Main_State", group=diag, raw=True)
        assert raw.conversion is not None and isinstance(state.samples[0], bytes)
        link = mdf.get("frame_type", group=groups["link h2e"])
        assert set(link.samples) <= {b"DATA", b"ACK", b"NAK", b"INVALID"}
        assert len(link.samples) == sum(r["kind"] == "frame" and r["direction"] == "h2e"
                                        for r in demo_json)
    finally:
        mdf.close()


def test_mcap_export_reads_back(demo: Path, demo_json: list[dict[str, Any]], tmp_path: Path,
                                capsys: pytest.CaptureFixture[str]) -> None:
    reader_mod = pytest.importorskip("mcap.reader", reason="the [export] extra is not installed")
    out_path = tmp_path / "demo.mcap"
    rc, _, err = _run(capsys, "export", str(demo), "--mcap", str(out_path), "--sw", "9.0")
    assert rc == 0, err
    import base64

    with out_path.open("rb") as fh:
        reader = reader_mod.make_reader(fh)
        summary = reader.get_summary()
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        assert meta["eyeq-spi"]["sw_release"] == "sw9"
        assert meta["eyeq-spi"]["capture_source"] == str(demo)
        # its own topics are JSON with a JSON Schema (the Foxglove scene's are tested in
        # tests/test_foxglove.py)
        own = [s for s in summary.schemas.values() if s.name.startswith("eyeq_spi.")]
        assert own and all(s.encoding == "jsonschema" for s in own)
        transfers: list[dict[str, Any]] = []
        messages: list[dict[str, Any]] = []
        for _schema, channel, message in reader.iter_messages():
            if not channel.topic.startswith(("/spi/", "/eyeq/")):
                continue
            body = json.loads(message.data)
            if channel.topic.endswith("/transfers"):
                transfers.append(body)
            elif channel.topic.startswith("/eyeq/"):
                assert channel.topic == f"/eyeq/{body['direction']}/{body['name']}"
                messages.append(body)
    frames = [r for r in demo_json if r["kind"] == "frame"]
    assert sorted(t["index"] for t in transfers) == [f["index"] for f in frames]
    assert all(len(base64.b64decode(t["data"])) == t["length"] for t in transfers)
    expect = [{k: r[k] for k in ("name", "fields", "errors")} for r in demo_json
              if r["kind"] == "message"]
    assert sorted(json.dumps(m, sort_keys=True) for m in
                  ({k: m[k] for k in ("name", "fields", "errors")} for m in messages)) == \
        sorted(json.dumps(m, sort_keys=True) for m in expect)


def test_export_errors(demo: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc, _, err = _run(capsys, "export", str(demo))
    assert rc == 2 and "--vcd" in err
    rc, _, err = _run(capsys, "export", str(demo), "--vcd", str(tmp_path / "no" / "dir.vcd"))
    assert rc == 2 and err.count("\n") == 1
    rc, _, err = _run(capsys, "export", str(tmp_path / "missing.pcapng"), "--vcd", "x.vcd")
    assert rc == 2 and err.count("\n") == 1


# -- replay -----------------------------------------------------------------------------------
def test_replay_into_host_follows_the_recorded_bring_up(
        demo: Path, demo_json: list[dict[str, Any]],
        capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, err = _run(capsys, "demo", "--virtual-time", "--duration", "0.8", "--json")
    recorded = [t["event"] for t in json.loads(out)["transitions"]]
    rc, out, err = _run(capsys, "replay", str(demo), "--into-host", "--json")
    got = json.loads(out)
    assert rc == 0 and got["ok"], err
    assert [t["event"] for t in got["transitions"]] == recorded
    assert got["state"] == "RUNNING_VISION" and got["e2e_errors"] == 0
    assert got["replay"]["complete"] and got["replay"]["host_naks"] == {}
    # as many ACKs as the recorded host sent (it missed one frame at the EyeQ's reset)
    recorded_acks = sum(r["kind"] == "frame" and r["direction"] == "h2e" and
                        r["frame_type"] == "ACK" for r in demo_json)
    assert got["replay"]["host_acks"] == recorded_acks
    assert got["received"]["EYEQ_VIS_OBSTACLES_MSG"] > 0
    assert got["side"] == "replay" and got["sent"]["HOST_VEH_STATE_MSG"] > 0


def test_replay_into_host_judges_as_host_does(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """A capture of a run that was not ok (a stream stopped): the replay is not ok either, names
    the problem, exits 1, and prints the summary schema of demo, host and sim."""
    from eyeq_spi.summary import KEYS

    cap = tmp_path / "stopped.pcapng"
    rc, out, _ = _run(capsys, "demo", "--virtual-time", "--duration", "3", "--json",
                      "--stop-dasp", "EYEQ_VIS_SRP_MSG@1.5", "--capture", str(cap))
    assert rc == 1 and "EYEQ_VIS_SRP_MSG" in json.loads(out)["problem"]
    rc, out, _ = _run(capsys, "replay", str(cap), "--into-host", "--json")
    got = json.loads(out)
    assert rc == 1 and not got["ok"] and "stale streams: EYEQ_VIS_SRP_MSG" in got["problem"]
    assert sorted(got) == sorted(KEYS)
    rc, out, _ = _run(capsys, "replay", str(cap), "--into-host")
    assert rc == 1 and out.startswith("replay: NOT OK") and "problem: stale streams" in out


def test_replay_into_host_judges_a_corrupted_capture(
        demo_records: list[Transfer], demo_json: list[dict[str, Any]], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A payload byte of every obstacles message flipped, link CRC recomputed: the frames pass
    the link, the host's E2E check (D5) catches them."""
    frames = FrameCodec()
    victims = {r["frames"][1] for r in demo_json
               if r["kind"] == "message" and r["name"] == "EYEQ_VIS_OBSTACLES_MSG"}
    path = tmp_path / "bad.pcapng"
    with CaptureWriter(path) as w:
        for i, r in enumerate(demo_records):
            data = r.data
            if i in victims:
                f = frames.decode(data)
                payload = bytearray(f.data)
                payload[60] ^= 0x40
                data = frames.data_frame(f.rsp, f.num, bytes(payload))
            w.write(r.direction or "h2e", r.time or 0.0, data)
    rc, out, _ = _run(capsys, "replay", str(path), "--into-host", "--json")
    got = json.loads(out)
    assert rc == 1 and not got["ok"] and got["e2e_errors"] >= len(victims) > 0


@pytest.mark.realtime
def test_replay_to_a_port_in_real_time(demo: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """1 s of the capture played over TCP to `eyeq-spi host` in another process: every frame
    ACKed, on time, and the host's requests answered at the link."""
    import subprocess
    import sys
    import time

    result: dict[str, Any] = {}

    def replay() -> None:
        result["rc"] = main(["replay", str(demo), "--listen", "tcp://127.0.0.1:0",
                             "--duration", "1.0", "--json"])

    capsys.readouterr()
    th = threading.Thread(target=replay, daemon=True)
    th.start()
    # poll for readiness: the replay names its listening URL (port 0: no race for a port)
    err, deadline = "", time.monotonic() + 30
    while "waiting for the host at " not in err and th.is_alive() \
            and time.monotonic() < deadline:
        th.join(0.02)
        err += capsys.readouterr().err
    assert "waiting for the host at " in err, (err, result)
    url = err.split("waiting for the host at ", 1)[1].split()[0]
    host = subprocess.run(
        [sys.executable, "-m", "eyeq_spi.cli", "host", "--port", url,
         "--duration", "3", "--json"], capture_output=True, text=True, timeout=60,
        cwd=Path(__file__).resolve().parents[1], check=False)
    th.join(30)
    out = capsys.readouterr().out
    summary = json.loads(out.strip().splitlines()[-1])
    got = summary["replay"]
    assert summary["side"] == "replay" and summary["address"] == url
    assert result.get("rc") == (0 if summary["ok"] else 1), out
    assert summary["ok"] or summary["problem"]
    assert got["played"] > 100 and got["host_acks"] >= 0.9 * got["played"], json.dumps(got)
    assert got["acks_sent"] >= 1 and got["host_messages"].get("GetEyeQExtendedState", 0) > 0, \
        (json.dumps(got), host.stdout[-3000:], host.stderr[-1000:])
    assert summary["received"] == got["host_messages"]
    assert summary["sent"].get("EYEQ_BOOT_STATUS_MSG", 0) >= 1, summary["sent"]
    assert got["max_lateness_ms"] < 500  # bounded; this loaded 2-core machine starves us
    host_summary = json.loads(host.stdout.strip().splitlines()[-1])
    assert host_summary["received"]["EYEQ_BOOT_STATUS_MSG"] >= 1, host.stderr[-1000:]

def test_missing_bench_extra_gives_the_pip_hint(demo: Path, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "asammdf", None)  # import asammdf raises ImportError
    monkeypatch.setitem(sys.modules, "mcap.writer", None)
    for opt in ("--mdf", "--mcap"):
        rc, _, err = _run(capsys, "export", str(demo), opt, str(tmp_path / "out"))
        assert rc == 2 and "pip install 'eyeq-spi[export]'" in err and err.count("\n") == 1


def test_replay_needs_an_eyeq_channel(demo_records: list[Transfer], tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "h2e.raw"
    path.write_bytes(b"".join(r.data for r in demo_records if r.direction == "h2e")[:128 * 20])
    rc, _, err = _run(capsys, "replay", str(path), "--into-host", "--direction", "h2e")
    assert rc == 2 and "no e2h transfer" in err and err.count("\n") == 1
    rc, _, err = _run(capsys, "replay", str(path), "--into-host", "--duration", "-1")
    assert rc == 2 and "--duration" in err
