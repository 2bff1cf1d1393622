"""The Lua dissector reads each capture with its own SW release (decision D4).

In order: the preference ``eyeq_spi.sw`` (``-o eyeq_spi.sw:8.1``); the capture's
``eyeq-spi sw=<release>`` packet comment; the release the EyeQ reports (boot status,
GetEyeQVersions reply, EYEQ_BASE_DIAG_STATUS_MSG); the release whose DASP layouts fit the payload
lengths; the newest. Every test compares with the Python stack's own view.
"""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from eyeq_spi.capture.pcapng_io import CaptureWriter, read_pcapng
from eyeq_spi.catalog.messages import sw_release_text
from eyeq_spi.catalog.schema import sw_key
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.link.frame import FrameCodec
from eyeq_spi.transport.segment import segment
from tests.test_wireshark import (
    LINK_FIELDS,
    TSHARK,
    check_application_fields,
    reassemble,
    run_demo,
    tshark,
    write_lua,
)

needs_tshark = pytest.mark.skipif(TSHARK is None, reason="tshark is not installed")
DIRECTIONS = ("h2e", "e2h")  # pcapng interfaces 0 and 1 (specs/capture.yaml)
RELEASE_FIELDS = ["frame.number", "eyeq_spi.message", "eyeq_spi.sw", "eyeq_spi.sw_source",
                  "_ws.expert.message"]


@pytest.fixture(scope="module")
def older_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s demo capture of SW 8.1, whose DASP layouts differ from the newest release's."""
    capture = tmp_path_factory.mktemp("demo81") / "c81.pcapng"
    run_demo(capture, "--sw", "8.1")
    return capture


def _block(kind: int, body: bytes) -> bytes:
    body += bytes(-len(body) % 4)
    return struct.pack("<II", kind, len(body) + 12) + body + struct.pack("<I", len(body) + 12)


def with_comment(capture: Path, out: Path, text: str | None) -> Path:
    """``capture``'s transfers in a pcapng of their own whose first packet carries ``text`` as
    its comment (as the capture writer records the release), or no comment at all."""
    with capture.open("rb") as fh:
        records = list(read_pcapng(fh))
    blocks = [_block(0x0A0D0D0A, struct.pack("<IHHq", 0x1A2B3C4D, 1, 0, -1))]
    for name in DIRECTIONS:  # USER0, microseconds, if_name
        blocks.append(_block(1, struct.pack("<HHIHH", 147, 0, 0, 2, len(name)) + name.encode()
                             + bytes(-len(name) % 4) + bytes(4)))
    for i, rec in enumerate(records):
        ts = round((rec.time or 0.0) * 1e6)
        body = struct.pack("<IIIII", DIRECTIONS.index(rec.direction or "h2e"), ts >> 32,
                           ts & 0xFFFFFFFF, len(rec.data), len(rec.data))
        body += rec.data + bytes(-len(rec.data) % 4)
        if i == 0 and text is not None:
            raw = text.encode()
            body += struct.pack("<HH", 1, len(raw)) + raw + bytes(-len(raw) % 4) + bytes(4)
        blocks.append(_block(6, body))
    out.write_bytes(b"".join(blocks))
    return out


def releases_of(rows: list[list[str]]) -> set[tuple[str, str]]:
    return {(r[2], r[3]) for r in rows if r[1]}


@needs_tshark
def test_an_older_release_reads_clean_and_agrees_field_by_field(
        tmp_path: Path, older_capture: Path) -> None:
    """A SW 8.1 capture without a recorded release: the boot status says 8.1; no length
    mismatch, no malformed message, every field as the Python codec of 8.1 decodes it."""
    lua = write_lua(tmp_path)
    older_capture = with_comment(older_capture, tmp_path / "plain.pcapng", None)
    rows = tshark(older_capture, lua, [*LINK_FIELDS, "eyeq_spi.sw", "eyeq_spi.sw_source"],
                  tmp_path)
    experts = " ".join(r[LINK_FIELDS.index("_ws.expert.message")] for r in rows)
    assert "mismatch" not in experts and "alformed" not in experts
    with older_capture.open("rb") as fh:
        records = list(read_pcapng(fh))
    codec = MessageCodec("8.1")
    messages = {n: codec.decode(data) for n, data in reassemble(records).items()}
    assert all(m.ok for m in messages.values())
    names = {i: r[LINK_FIELDS.index("eyeq_spi.message")] for i, r in enumerate(rows, 1)
             if r[LINK_FIELDS.index("eyeq_spi.message")]}
    assert names == {n: m.name for n, m in messages.items()}
    assert {(r[-2], r[-1]) for r in rows if r[-2]} == {("8.1", "boot status")}
    check_application_fields(older_capture, lua, tmp_path, codec, messages)


@needs_tshark
def test_the_capture_comment_wins_and_the_preference_overrides(
        tmp_path: Path, older_capture: Path) -> None:
    lua = write_lua(tmp_path)
    # the comment names the release although the EyeQ reports another (the demo's own
    # capture may record its release already: each capture here is written afresh)
    noted = with_comment(older_capture, tmp_path / "noted.pcapng", "eyeq-spi sw=9.0")
    rows = tshark(noted, lua, RELEASE_FIELDS, tmp_path)
    assert releases_of(rows) == {("9.0", "capture")}
    assert any("length mismatch" in r[4] for r in rows)  # 8.1 traffic read as 9.0
    # a comment naming a release specs/ does not list is no evidence
    odd = with_comment(older_capture, tmp_path / "odd.pcapng", "eyeq-spi sw=1.7")
    assert releases_of(tshark(odd, lua, RELEASE_FIELDS, tmp_path)) == {("8.1", "boot status")}
    # the preference overrides, with one note naming both
    plain = with_comment(older_capture, tmp_path / "plain.pcapng", None)
    rows = tshark(plain, lua, RELEASE_FIELDS, tmp_path,
                  options=("-o", "eyeq_spi.sw:9.0"))
    assert releases_of(rows) == {("9.0", "preference")}
    notes = [r[0] for r in rows if "read as SW 9.0 (preference) although the capture says "
             "SW 8.1 (boot status)" in r[4]]
    assert notes == ["1"]
    # the generator's --sw sets the preference's default
    fixed = tmp_path / "fixed.lua"
    from eyeq_spi.wireshark import generate_lua

    fixed.write_text(generate_lua("8.1"), encoding="utf-8")
    rows = tshark(noted, fixed, RELEASE_FIELDS, tmp_path)
    assert releases_of(rows) == {("8.1", "preference")}
    assert not any("mismatch" in r[4] for r in rows)


def fitting_release(pairs: set[tuple[int, int]]) -> str:
    """The newest release whose DASP layouts fit the most (data ID, message length) pairs."""
    cat = MessageCodec().cat
    score = {}
    for key in cat.sw_versions:
        codec = MessageCodec(key, cat)
        n = 0
        for data_id, length in pairs:
            msg = codec.dasp_message(data_id)
            if msg is not None and codec.layout(msg).size == length - 4:
                n += 1
        score[key] = n
    best = max(score.values())
    return sw_release_text(max((k for k in score if score[k] == best), key=sw_key))


@needs_tshark
@pytest.mark.parametrize("sw", ["8.1", "4.0"])
def test_without_a_report_the_payload_lengths_decide(tmp_path: Path, sw: str) -> None:
    """Mid-stream traffic (no boot, no versions reply): the release whose layouts fit."""
    codec = MessageCodec(sw)
    fc = FrameCodec()
    names = ["EYEQ_VIS_OBSTACLES_MSG", "EYEQ_VIS_TRAFFIC_SIGNS_MSG", "EYEQ_VIS_ROAD_DATA_MSG",
             "EYEQ_VIS_LIGHT_SENSOR_DATA_MSG", "EYEQ_DYNAMIC_CAL_MSG"]
    capture = tmp_path / "mid.pcapng"  # written by our writer, then stripped of its release
    pairs = set()
    num, t = 0, 0.0
    with CaptureWriter(capture) as w:
        for tid, name in enumerate(n for n in names if codec.cat.message(n).exists_in(codec.sw)):
            msg = codec.cat.message(name)
            data = codec.encode_dasp(name, codec.layout(msg).zero_values(), counter=tid)
            pairs.add((msg.data_id, len(data)))
            for part in segment(data, tid):
                w.write("e2h", t, fc.data_frame(0, num, part))
                num, t = num + 1, t + 0.001
    expect = fitting_release(pairs)
    capture = with_comment(capture, tmp_path / "plain.pcapng", None)  # a foreign capture
    lua = write_lua(tmp_path)
    # one pass decides as it goes: the last message is read with what all of them say
    rows = [r for r in tshark(capture, lua, RELEASE_FIELDS, tmp_path) if r[1]]
    assert rows[-1][2] == expect and rows[-1][3].startswith("DASP payload lengths (fit ")
    # two passes (tshark -2) read every message with it
    rows = tshark(capture, lua, RELEASE_FIELDS, tmp_path, two_pass=True)
    found = releases_of(rows)
    assert {r for r, _ in found} == {expect}, found
    assert all(src.startswith("DASP payload lengths (fit ") for _, src in found)
    assert not any("mismatch" in r[4] for r in rows)


def test_sniff_window_matches_dissect() -> None:
    """The dissector looks for the release in as many transfers as ``eyeq-spi dissect``: both
    read ``release_sniff_transfers`` of ``specs/capture.yaml``."""
    from eyeq_spi.capture.pcapng_io import release_sniff_transfers
    from eyeq_spi.wireshark.lua_gen import generate_lua

    n = release_sniff_transfers()
    assert n > 0
    assert f"local SNIFF_RECORDS = {n}\n" in generate_lua(None)

