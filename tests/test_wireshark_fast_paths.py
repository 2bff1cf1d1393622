"""The Lua dissector's shortcuts give what the full decoding gives.

The dissector sums the CRC of a frame whose tail is zero only up to the tail, reads header, CRC
and transport bytes with one call, adds no item that no filter, column or tap references and
builds the Info text once per frame. These tests run tshark on frames made for each shortcut
(and for where it must not apply) and compare with the Python stack, and the Info text of
summary lines (a tree that is not shown) with the one of a tree that is shown.
"""

from __future__ import annotations

import os
import struct
import subprocess
from pathlib import Path

import pytest

from eyeq_spi.capture.pcapng_io import CaptureWriter, read_pcapng
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.link.frame import Frame, FrameCodec, FrameKind
from eyeq_spi.transport.segment import segment
from eyeq_spi.wireshark.lua_crc import SHORT
from tests.test_wireshark import (
    TSHARK,
    expected_link,
    needs_tshark,
    run_demo,
    tshark,
    write_lua,
)


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s demo capture of the newest release."""
    capture = tmp_path_factory.mktemp("demo") / "c.pcapng"
    run_demo(capture)
    return capture


def crc_cases() -> list[tuple[str, bytes]]:
    """Frames on both sides of the zero-tail shortcut, with good and bad CRCs."""
    fc = FrameCodec()
    codec = MessageCodec()
    request = codec.mesp.encode_request("GetEyeQExtendedState", 5, {})
    short = fc.data_frame(0, 0, segment(request, 0)[0])  # zeros from byte 14 on
    assert not any(short[SHORT:])
    tail_set = bytearray(short)
    tail_set[-1] = 1  # a byte in the tail, after the CRC was computed: a bad CRC
    edge_set = bytearray(short)
    edge_set[SHORT] = 0x80  # the first byte the shortcut leaves out: a bad CRC too
    last_in = bytearray(short)
    last_in[SHORT - 1] = 0x40  # the last byte the shortcut sums: a bad CRC as well
    bad_short = bytearray(short)
    bad_short[4] ^= 0x01  # a CRC that does not match a frame with a zero tail
    full = fc.encode(Frame(FrameKind.DATA, 0, 0, 3, bytes([0, 9]) + bytes(range(1, 121))))
    good_tail = fc.encode(Frame(FrameKind.DATA, 0, 0, 4, bytes([0, 5]) + request
                                + bytes(114) + b"\x07"))  # CRC over a nonzero last byte
    ack_bad = bytearray(fc.ack(5))
    ack_bad[5] ^= 0x10
    return [
        ("h2e", short), ("h2e", bytes(tail_set)), ("h2e", bytes(edge_set)),
        ("h2e", bytes(last_in)), ("h2e", bytes(bad_short)), ("e2h", full),
        ("h2e", good_tail), ("e2h", fc.ack(0)), ("e2h", bytes(ack_bad)),
    ]


def write_capture(path: Path, frames: list[tuple[str, bytes]]) -> Path:
    with CaptureWriter(path) as w:
        for i, (direction, data) in enumerate(frames):
            w.write(direction, 0.001 * i, data)
    return path


def summary_info(capture: Path, lua: Path, home: Path, *options: str) -> list[str]:
    """The Info column of tshark's summary lines (a tree that is not shown)."""
    assert TSHARK is not None
    cmd = [TSHARK, "-r", str(capture), "-X", f"lua_script:{lua}", "-o", "gui.column.format:"
           '"No.","%m","Info","%i"', *options]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False,
                          env={**os.environ, "HOME": str(home)})
    assert proc.returncode == 0, proc.stderr
    assert "Lua: Error" not in proc.stderr, proc.stderr
    return [line.strip().split(" ", 1)[1].strip() for line in proc.stdout.splitlines()
            if line.strip()]


@needs_tshark
def test_crc_shortcut_agrees_with_python(tmp_path: Path) -> None:
    frames = crc_cases()
    capture = write_capture(tmp_path / "crc.pcapng", frames)
    lua = write_lua(tmp_path)
    fields = ["eyeq_spi.crc_ok", "eyeq_spi.crc_computed", "eyeq_spi.crc"]
    fc = FrameCodec()
    with capture.open("rb") as fh:
        records = list(read_pcapng(fh))
    expect_ok = [row["eyeq_spi.crc_ok"] for row in expected_link(records)]
    assert expect_ok == ["1", "0", "0", "0", "0", "1", "1", "1", "0"]
    for two_pass in (False, True):
        rows = tshark(capture, lua, fields, tmp_path, two_pass=two_pass)
        assert [r[0] for r in rows] == expect_ok
        for (_, data), (_, computed, _) in zip(frames, rows, strict=True):
            f = fc.decode(data)
            want = fc.compute_crc(f.d, data[:4], data[6:])
            assert int(computed, 16) == want
    # summary lines (no tree shown) mark the same frames
    marked = ["[bad CRC]" in info for info in summary_info(capture, lua, tmp_path)]
    assert marked == [ok == "0" for ok in expect_ok]


@needs_tshark
def test_summary_info_equals_shown_tree_info(tmp_path: Path, demo: Path) -> None:
    """Info text of summary lines (tree not shown, nothing referenced) is the Info text of a
    shown tree (-T fields), on the demo capture and on frames with faults."""
    lua = write_lua(tmp_path)
    faults = write_capture(tmp_path / "faults.pcapng", crc_cases())
    for capture in (demo, faults):
        summary = summary_info(capture, lua, tmp_path)
        shown = [r[0] for r in tshark(capture, lua, ["_ws.col.Info"], tmp_path)]
        assert summary == shown
        # and with a filter that references a payload member (items added, tree not shown)
        filtered = summary_info(capture, lua, tmp_path, "-Y",
                                "eyeq_spi.crc_ok == 0 || eyeq_spi.transport")
        assert set(filtered) <= set(shown)
    info = summary_info(faults, lua, tmp_path)
    assert info[0] == "h2e DATA NUM=0 RSP=0 single: GetEyeQExtendedState request"
    assert info[1] == "h2e DATA NUM=0 RSP=0 [bad CRC] single"
    assert info[7] == "e2h ACK of NUM=0"
    assert info[8] == "e2h ACK of NUM=5 [bad CRC]"


@needs_tshark
def test_details_tree_is_built_where_shown(tmp_path: Path) -> None:
    """tshark -V shows every frame's whole tree, with the expert info of the bad CRCs."""
    assert TSHARK is not None
    frames = crc_cases()
    capture = write_capture(tmp_path / "crc.pcapng", frames)
    lua = write_lua(tmp_path)
    proc = subprocess.run([TSHARK, "-r", str(capture), "-X", f"lua_script:{lua}", "-V"],
                          capture_output=True, text=True, timeout=120, check=False,
                          env={**os.environ, "HOME": str(tmp_path)})
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert out.count("EyeQ4 SPI") == len(frames)
    assert out.count("[Expert Info (Error/Checksum): CRC 0x") == 5  # each bad CRC
    assert out.count("Header word: ") == len(frames)
    assert "GetEyeQExtendedState" in out


def write_pcap(path: Path, frames: list[tuple[str, bytes]]) -> Path:
    """A classic pcap of link type USER0: no interfaces, so no direction."""
    out = bytearray(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 147))
    for i, (_, data) in enumerate(frames):
        out += struct.pack("<IIII", 0, 1000 * i, len(data), len(data)) + data
    path.write_bytes(bytes(out))
    return path


@needs_tshark
def test_capture_without_interfaces(tmp_path: Path) -> None:
    """A capture with no interfaces (pcap) is decoded with direction "?" in every pass that
    builds a tree, one pass or two."""
    capture = write_pcap(tmp_path / "crc.pcap", crc_cases())
    lua = write_lua(tmp_path)
    for options in ((), ("-2",)):
        info = summary_info(capture, lua, tmp_path, *options)
        assert info[0] == "DATA NUM=0 RSP=0 single: GetEyeQExtendedState request"
        assert info[8] == "ACK of NUM=5 [bad CRC]"
    rows = tshark(capture, lua, ["eyeq_spi.dir", "eyeq_spi.message"], tmp_path)
    assert rows[0] == ["", "GetEyeQExtendedState"]


@needs_tshark
def test_chunks_padding_and_info_names(tmp_path: Path) -> None:
    """Singles, first and consecutive chunks are cut at their offsets, the zero padding after a
    message's last byte is searched up to the frame's last byte, and the Info texts made once
    per transfer ID and per message and counter stay per message."""
    fc = FrameCodec()
    codec = MessageCodec()
    base = codec.cat.message("EYEQ_BASE_DIAG_STATUS_MSG")
    aeb = codec.cat.message("EYEQ_VIS_AEB_INFO_MSG")
    dasp = codec.encode_dasp(base.name, codec.layout(base).zero_values(), counter=7)
    single = codec.encode_dasp(aeb.name, codec.layout(aeb).zero_values(), counter=7)
    parts = segment(dasp, 3)
    assert len(parts) == 2 and len(parts[1]) < 122
    again = segment(dasp, 4)
    last_set = again[1] + bytes(121 - len(again[1])) + b"\x01"  # only the frame's last byte
    frames = [
        ("e2h", fc.data_frame(0, 0, segment(single, 0)[0])),  # 1: a single, counter 7
        ("e2h", fc.data_frame(0, 1, parts[0])),  # 2
        ("e2h", fc.data_frame(0, 2, parts[1])),  # 3: complete, counter 7, another message
        ("e2h", fc.data_frame(0, 3, again[0])),  # 4
        ("e2h", fc.data_frame(0, 4, last_set)),  # 5: a nonzero last byte: bad padding
        ("e2h", fc.data_frame(0, 5, segment(single, 0)[0])),  # 6: the first message again
    ]
    assert len(frames[4][1]) == 128
    capture = write_capture(tmp_path / "chunks.pcapng", frames)
    lua = write_lua(tmp_path)
    info = summary_info(capture, lua, tmp_path)
    assert info[0] == f"e2h DATA NUM=0 RSP=0 single: {aeb.name} #7"
    assert info[1] == "e2h DATA NUM=1 RSP=0 first ID=3 total=" + str(len(dasp))
    assert info[2] == f"e2h DATA NUM=2 RSP=0 consecutive ID=3: {base.name} #7"
    assert info[4] == "e2h DATA NUM=4 RSP=0 consecutive ID=4"
    assert info[5] == f"e2h DATA NUM=5 RSP=0 single: {aeb.name} #7"
    rows = tshark(capture, lua, ["eyeq_spi.msg_length", "_ws.expert.message"], tmp_path)
    assert rows[0][0] == str(len(single)) and rows[2][0] == str(len(dasp))
    assert "bad_padding" in rows[4][1]
