"""The generated Wireshark Lua dissector, run by tshark, against the Python stack's own view.

The Python side here is independent of the Lua: frames through ``FrameCodec``, a small reference
reassembler written from decisions T1-T6, and ``MessageCodec`` for the application layer.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
from collections import Counter
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi.capture.pcapng_io import CaptureWriter, Transfer, read_pcapng
from eyeq_spi.codec.layout import Layout
from eyeq_spi.codec.message import DecodedMessage, MessageCodec
from eyeq_spi.errors import SpecError
from eyeq_spi.link.frame import FRAME_SIZE, Frame, FrameCodec, FrameKind, NakReason
from eyeq_spi.transport.segment import (
    CONSECUTIVE,
    CONSECUTIVE_CHUNK,
    FIRST,
    FIRST_CHUNK,
    SINGLE,
    SINGLE_MAX,
    segment,
)
from eyeq_spi.wireshark import generate_lua

ROOT = Path(__file__).resolve().parents[1]
TSHARK = shutil.which("tshark")
needs_tshark = pytest.mark.skipif(TSHARK is None, reason="tshark is not installed")

LINK_FIELDS = [
    "frame.number", "eyeq_spi.dir", "eyeq_spi.frame_type", "eyeq_spi.num", "eyeq_spi.rsp",
    "eyeq_spi.crc_ok", "eyeq_spi.nak_reason", "eyeq_spi.transport", "eyeq_spi.transfer_id",
    "eyeq_spi.total", "eyeq_spi.size", "eyeq_spi.bad_length", "eyeq_spi.app_protocol",
    "eyeq_spi.message", "_ws.expert.message",
]
TRANSPORT_NAMES = {SINGLE: "single", FIRST: "first", CONSECUTIVE: "consecutive"}


# -- Lua source checks ----------------------------------------------------------------------------
def strip_lua_strings(code: str) -> str:
    """The code with every comment and string literal (short and long) removed."""
    out: list[str] = []
    i, n = 0, len(code)
    long_open = re.compile(r"\[(=*)\[")
    while i < n:
        if code.startswith("--", i):
            m = long_open.match(code, i + 2)
            if m:
                end = code.find("]" + m.group(1) + "]", m.end())
                i = n if end < 0 else end + len(m.group(1)) + 2
            else:
                end = code.find("\n", i)
                i = n if end < 0 else end
            continue
        ch = code[i]
        m = long_open.match(code, i) if ch == "[" else None
        if m:
            end = code.find("]" + m.group(1) + "]", m.end())
            i = n if end < 0 else end + len(m.group(1)) + 2
            out.append('""')
            continue
        if ch in "\"'":
            j = i + 1
            while j < n and code[j] != ch:
                j += 2 if code[j] == "\\" else 1
            i = j + 1
            out.append('""')
            continue
        out.append(ch)
        i += 1
    return "".join(out)


LUA53 = re.compile(r"//|&|\||<<|>>|~(?!=)")


def test_strip_lua_strings_keeps_code_only() -> None:
    code = 'local a = "x // y & z" .. \'|\' -- a | b\nlocal b = [[ ~ ]] --[==[ >> ]==] ~= 1'
    assert not LUA53.search(strip_lua_strings(code))
    assert LUA53.search(strip_lua_strings("local c = a // b"))
    assert LUA53.search(strip_lua_strings("local c = a ~ b"))


def test_generated_lua_is_lua52(tmp_path: Path) -> None:
    lua = generate_lua()
    (tmp_path / "eyeq_spi.lua").write_text(lua, encoding="utf-8")
    code = strip_lua_strings(lua)
    bad = [(no, line) for no, line in enumerate(code.splitlines(), 1) if LUA53.search(line)]
    assert not bad, f"Lua 5.3 operators in the generated code: {bad[:5]}"
    assert 'Proto("eyeq_spi", "EyeQ4 SPI")' in lua
    assert 'DissectorTable.get("wtap_encap"):add(wtap.USER0, p)' in lua
    assert 'Field.new("frame.interface_id")' in lua


# -- tshark ---------------------------------------------------------------------------------------
def tshark(capture: Path, lua: Path, fields: list[str], home: Path,
           two_pass: bool = False, options: tuple[str, ...] = ()) -> list[list[str]]:
    assert TSHARK is not None
    cmd = [TSHARK, "-r", str(capture), "-X", f"lua_script:{lua}", "-T", "fields",
           "-E", "separator=/t", "-E", "occurrence=a", "-E", "aggregator=,", *options]
    if two_pass:
        cmd.append("-2")
    for f in fields:
        cmd += ["-e", f]
    env = {**os.environ, "HOME": str(home)}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "Lua: Error" not in proc.stderr, proc.stderr
    assert "Lua Error" not in proc.stdout, proc.stdout[:2000]
    rows = [line.split("\t") for line in proc.stdout.splitlines()]
    assert all(len(r) == len(fields) for r in rows)
    return rows


def write_lua(tmp_path: Path) -> Path:
    path = tmp_path / "eyeq_spi.lua"
    path.write_text(generate_lua(), encoding="utf-8")
    return path


# -- the Python reference -------------------------------------------------------------------------
def expected_link(records: list[Transfer]) -> list[dict[str, str]]:
    """Per frame, what tshark must print for LINK_FIELDS[1:12]."""
    fc = FrameCodec()
    out = []
    for rec in records:
        row = dict.fromkeys(LINK_FIELDS[1:12], "")
        row["eyeq_spi.dir"] = rec.direction or ""
        out.append(row)
        if len(rec.data) != FRAME_SIZE:
            row["eyeq_spi.bad_length"] = "1"
            continue
        f = fc.decode(rec.data)
        kind = f.kind
        row["eyeq_spi.frame_type"] = kind.name if kind is not None else "INVALID"
        row["eyeq_spi.num"] = str(f.num)
        row["eyeq_spi.rsp"] = str(f.rsp)
        row["eyeq_spi.crc_ok"] = "1" if fc.crc_ok(rec.data, f) else "0"
        if kind is FrameKind.NAK:
            row["eyeq_spi.nak_reason"] = str(f.num)
        if kind is FrameKind.DATA:
            ttype = f.data[0]
            row["eyeq_spi.transport"] = TRANSPORT_NAMES.get(ttype, "invalid")
            if ttype in (FIRST, CONSECUTIVE):
                row["eyeq_spi.transfer_id"] = str(f.data[1])
            if ttype == FIRST:
                row["eyeq_spi.total"] = str(int.from_bytes(f.data[2:6], "little"))
            if ttype == SINGLE:
                row["eyeq_spi.size"] = str(f.data[1])
    return out


def reassemble(records: list[Transfer]) -> dict[int, bytes]:
    """Frame number (1-based) -> the message that frame completed (T1-T6a, trusted frames only)."""
    fc = FrameCodec()
    open_: dict[str | None, dict[str, Any] | None] = {}
    out: dict[int, bytes] = {}
    for number, rec in enumerate(records, 1):
        if len(rec.data) != FRAME_SIZE:
            continue
        f = fc.decode(rec.data)
        if f.kind is not FrameKind.DATA or f.r != 0 or not fc.crc_ok(rec.data, f):
            continue
        data, o = f.data, open_.get(rec.direction)
        if data[0] == SINGLE and 1 <= data[1] <= SINGLE_MAX:
            open_[rec.direction] = None
            out[number] = bytes(data[2 : 2 + data[1]])
        elif data[0] == FIRST:
            total = int.from_bytes(data[2:6], "little")
            open_[rec.direction] = {"id": data[1], "total": total, "last": f.num,
                                    "buf": bytearray(data[6 : 6 + FIRST_CHUNK])}
        elif data[0] == CONSECUTIVE and o is not None:
            if data[1] != o["id"] or f.num != (o["last"] + 1) % 4096:
                open_[rec.direction] = None
                continue
            take = min(CONSECUTIVE_CHUNK, o["total"] - len(o["buf"]))
            if any(data[2 + take :]):  # T4/T6a: the padding after the message is zero
                open_[rec.direction] = None
                continue
            o["buf"] += data[2 : 2 + take]
            o["last"] = f.num
            if len(o["buf"]) >= o["total"]:
                out[number] = bytes(o["buf"])
                open_[rec.direction] = None
    return out


def flatten(lay: Layout, values: dict[str, Any], out: dict[str, list[Any]]) -> None:
    """eyeq_spi.<struct>.<member> -> values in document order, as the dissector shows them."""
    for f in lay.fields:
        v = values[f.name]
        items = v if f.count else [v]
        child = lay.children.get(f.name)
        if child is not None:
            for item in items:
                flatten(child, item, out)
        else:
            out.setdefault(f"eyeq_spi.{lay.name}.{f.name}", []).extend(items)


def all_member_fields(codec: MessageCodec) -> list[str]:
    names: dict[str, None] = {}

    def walk(lay: Layout) -> None:
        for f in lay.fields:
            child = lay.children.get(f.name)
            if child is not None:
                walk(child)
            else:
                names[f"eyeq_spi.{lay.name}.{f.name}"] = None

    for msg in codec.cat.messages:
        if msg.protocol != "DASP" or msg.exists_in(codec.sw):
            walk(codec.layout(msg))
    return list(names)


def mesp_field_names(codec: MessageCodec) -> dict[tuple[str, str], str]:
    """(function, param) -> filter name: eyeq_spi.mesp.<param>, qualified if types differ."""
    types: dict[str, set[str]] = {}
    for fn in codec.cat.mesp:
        for p in (*fn.request, *fn.reply):
            types.setdefault(p.name, set()).add(p.type)
    out = {}
    for fn in codec.cat.mesp:
        for p in (*fn.request, *fn.reply):
            qual = f"{fn.name}." if len(types[p.name]) > 1 else ""
            out[(fn.name, p.name)] = f"eyeq_spi.mesp.{qual}{p.name}"
    return out


def same(printed: str, value: Any) -> bool:
    if isinstance(value, float):
        got = float(printed)
        if math.isnan(value):
            return math.isnan(got)
        return math.isclose(got, value, rel_tol=1e-5, abs_tol=1e-37)
    if isinstance(value, bool):
        return printed in (("1", "True") if value else ("0", "False"))
    if isinstance(value, bytes | bytearray):
        return printed.replace(":", "").lower() == bytes(value).hex()
    if isinstance(value, int):
        return int(printed, 0) == value
    return printed == str(value)


def compare_values(where: str, printed: str, values: Iterable[Any]) -> None:
    vals = list(values)
    got = printed.split(",") if printed else []
    assert len(got) == len(vals), f"{where}: tshark {printed[:200]!r}, Python {vals[:20]}"
    for i, (p, v) in enumerate(zip(got, vals, strict=True)):
        assert same(p, v), f"{where}[{i}]: tshark {p!r}, Python {v!r}"


def run_demo(capture: Path, *extra: str) -> dict[str, Any]:
    demo = subprocess.run(
        [sys.executable, "-m", "eyeq_spi.cli", "demo", "--virtual-time", "--duration", "3",
         "--capture", str(capture), "--json", *extra],
        cwd=ROOT, capture_output=True, text=True, timeout=120, check=False,
    )
    assert demo.returncode == 0, demo.stderr[-2000:]
    summary: dict[str, Any] = json.loads(demo.stdout.strip().splitlines()[-1])
    return summary


@pytest.fixture(scope="module")
def demo_capture(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """A 3 s demo capture of the newest release and the demo's own summary."""
    capture = tmp_path_factory.mktemp("demo") / "c.pcapng"
    return capture, run_demo(capture)


# -- test: the demo's capture ---------------------------------------------------------------------
@needs_tshark
def test_demo_capture_matches_python(tmp_path: Path,
                                     demo_capture: tuple[Path, dict[str, Any]]) -> None:
    capture, summary = demo_capture
    lua = write_lua(tmp_path)
    with capture.open("rb") as fh:
        records = list(read_pcapng(fh))

    # link and transport fields, frame by frame; two passes exercise the stored reassembly
    rows = tshark(capture, lua, LINK_FIELDS, tmp_path, two_pass=True)
    assert len(rows) == len(records)
    expect = expected_link(records)
    for number, (row, exp) in enumerate(zip(rows, expect, strict=True), 1):
        got = dict(zip(LINK_FIELDS, row, strict=True))
        assert got["frame.number"] == str(number)
        for name, value in exp.items():
            if name == "eyeq_spi.nak_reason" and value:
                assert int(got[name], 0) == int(value), f"frame {number} {name}"
            else:
                assert got[name] == value, f"frame {number} {name}: {got[name]!r} != {value!r}"
        assert "mismatch" not in got["_ws.expert.message"], f"frame {number}"
        assert "Malformed" not in got["_ws.expert.message"], f"frame {number}"

    # messages: the same frames complete the same messages
    codec = MessageCodec()
    messages = {n: codec.decode(data) for n, data in reassemble(records).items()}
    tshark_names = {i: row[LINK_FIELDS.index("eyeq_spi.message")]
                    for i, row in enumerate(rows, 1)
                    if row[LINK_FIELDS.index("eyeq_spi.message")]}
    assert tshark_names == {n: m.name for n, m in messages.items()}
    for n, m in messages.items():
        assert rows[n - 1][LINK_FIELDS.index("eyeq_spi.app_protocol")] == m.protocol
        assert m.ok, f"frame {n}: {m.errors}"
    # ... and as many of each as the demo itself counted
    counts = Counter(m.name for m in messages.values())
    for name, count in summary["received"].items():
        assert counts[name] == count, name
    multi = {m.name for n, m in messages.items()
             if rows[n - 1][LINK_FIELDS.index("eyeq_spi.transport")] != "single"}
    assert "EYEQ_VIS_OBSTACLES_MSG" in multi
    assert any(m.protocol == "MESP" for m in messages.values())

    check_application_fields(capture, lua, tmp_path, codec, messages)


def check_application_fields(capture: Path, lua: Path, home: Path, codec: MessageCodec,
                             messages: dict[int, DecodedMessage]) -> None:
    members = all_member_fields(codec)
    mesp_names = mesp_field_names(codec)
    header = ["eyeq_spi.dasp.data_id", "eyeq_spi.dasp.counter", "eyeq_spi.msg_id",
              "eyeq_spi.mesp.service", "eyeq_spi.mesp.function", "eyeq_spi.mesp.tag",
              "eyeq_spi.mesp.counter", "eyeq_spi.mesp.reply", "eyeq_spi.mesp.name",
              "eyeq_spi.mesp.ret"]
    params = sorted(set(mesp_names.values()))
    fields = ["frame.number", *header, *params, *members]
    for sample in ("eyeq_spi.EYEQ_VIS_OBSTACLES_MSG.timestamp_ms",
                   "eyeq_spi.eyeq_vision_object_t.id",
                   "eyeq_spi.eyeq_object_physical_state_t.longDistance",
                   "eyeq_spi.EYEQ_DIAGNOSTIC_MSG.Main_State"):
        assert sample in members
    rows = {int(r[0]): dict(zip(fields, r, strict=True))
            for r in tshark(capture, lua, fields, home)}
    checked: Counter[str] = Counter()
    for n, m in messages.items():
        got = rows[n]
        if m.protocol == "MESP":
            exp_header: dict[str, Any] = {
                f"eyeq_spi.mesp.{k}": v for k, v in m.header.items()}
            exp_header["eyeq_spi.mesp.name"] = m.name
            for name, value in exp_header.items():
                compare_values(f"frame {n} {name}", got[name], [value])
            expect = {mesp_names[(m.name or "", k)]: v for k, v in m.fields.items() if k != "ret"}
            if "ret" in m.fields:
                compare_values(f"frame {n} ret", got["eyeq_spi.mesp.ret"], [m.fields["ret"]])
            for name in params:
                value = expect.get(name)
                values = [] if value is None or value == b"" else [value]
                compare_values(f"frame {n} {name}", got[name], values)
            checked["MESP"] += 1
            continue
        if m.protocol == "DASP":
            compare_values(f"frame {n} data_id", got["eyeq_spi.dasp.data_id"],
                           [m.header["data_id"]])
            compare_values(f"frame {n} counter", got["eyeq_spi.dasp.counter"],
                           [m.header["counter"]])
        else:
            compare_values(f"frame {n} id", got["eyeq_spi.msg_id"], [m.header["id"]])
        flat: dict[str, list[Any]] = {}
        flatten(codec.layout(codec.cat.message(m.name or "")), m.fields, flat)
        for name in members:
            compare_values(f"frame {n} {m.name} {name}", got[name], flat.get(name, []))
        checked[m.name or ""] += 1
    assert checked["MESP"] > 0
    assert checked["EYEQ_VIS_OBSTACLES_MSG"] > 0
    assert checked["EYEQ_DIAGNOSTIC_MSG"] > 0


# -- test: a tiny capture with every link-layer case ----------------------------------------------
@needs_tshark
@pytest.mark.parametrize("two_pass", [False, True])
def test_link_cases(tmp_path: Path, two_pass: bool) -> None:
    fc = FrameCodec()
    codec = MessageCodec()
    request = codec.mesp.encode_request("GetEyeQExtendedState", 5, {})
    good = fc.data_frame(0, 0, segment(request, 0)[0])
    flipped = bytearray(fc.data_frame(0, 1, segment(request, 0)[0]))
    flipped[4] ^= 0xFF
    aeb = codec.cat.message("EYEQ_BASE_DIAG_STATUS_MSG")
    dasp = codec.encode_dasp(aeb.name, codec.layout(aeb).zero_values(), counter=7)
    broken = segment(dasp, 3)
    whole = segment(dasp, 4)
    assert len(broken) == 2
    aeb_lay = codec.layout(codec.cat.message("EYEQ_VIS_AEB_INFO_MSG"))
    aeb_msg = codec.encode_dasp("EYEQ_VIS_AEB_INFO_MSG",
                                {**aeb_lay.zero_values(), "timestamp_ms": 4242}, counter=9)
    padded = segment(dasp, 5)[1] + b"\xab"  # a byte after the message's last: not this transfer
    frames: list[tuple[str, bytes]] = [
        ("h2e", good),                                                # 1
        ("e2h", fc.ack(0)),                                           # 2
        ("e2h", fc.nak(1, NakReason.CRC_MISMATCH)),                   # 3
        ("h2e", bytes(flipped)),                                      # 4
        ("e2h", fc.data_frame(0, 9, b"\x00\x01\x01")[:127]),          # 5
        ("h2e", fc.encode(Frame(0x1, 0, 0, 2, bytes(122)))),          # 6
        ("e2h", fc.data_frame(0, 0, broken[0])),                      # 7
        ("e2h", fc.data_frame(0, 2, broken[1])),                      # 8: NUM gap
        ("e2h", fc.data_frame(0, 3, whole[0])),                       # 9
        ("e2h", fc.data_frame(0, 4, whole[1])),                       # 10: complete
        ("e2h", fc.data_frame(0, 5, segment(aeb_msg, 0)[0])),        # 11
        ("e2h", fc.data_frame(0, 6, segment(aeb_msg[:-1], 0)[0])),   # 12: payload too short
        ("e2h", fc.data_frame(0, 7, segment(b"\xee\x01\x02", 0)[0])),  # 13: unknown
        ("e2h", fc.data_frame(0, 8, segment(dasp, 5)[0])),           # 14
        ("e2h", fc.data_frame(0, 9, padded)),                         # 15: bad padding (T6a)
    ]
    capture = tmp_path / "tiny.pcapng"
    with CaptureWriter(capture) as w:
        for i, (direction, data) in enumerate(frames):
            w.write(direction, 0.001 * i, data)
    rows = tshark(capture, write_lua(tmp_path), LINK_FIELDS, tmp_path, two_pass=two_pass)
    got = [dict(zip(LINK_FIELDS, r, strict=True)) for r in rows]
    cols = LINK_FIELDS[1:14]
    table = [[g[c] for c in cols] for g in got]
    assert table == [
        # dir, type, num, rsp, crc_ok, nak, transport, id, total, size, bad_len, proto, message
        ["h2e", "DATA", "0", "0", "1", "", "single", "", "", "5", "", "MESP",
         "GetEyeQExtendedState"],
        ["e2h", "ACK", "0", "0", "1", "", "", "", "", "", "", "", ""],
        ["e2h", "NAK", "2", "1", "1", "0x0002", "", "", "", "", "", "", ""],
        ["h2e", "DATA", "1", "0", "0", "", "single", "", "", "5", "", "", ""],
        ["e2h", "", "", "", "", "", "", "", "", "", "1", "", ""],
        ["h2e", "INVALID", "2", "0", "1", "", "", "", "", "", "", "", ""],
        ["e2h", "DATA", "0", "0", "1", "", "first", "3", str(len(dasp)), "", "", "", ""],
        ["e2h", "DATA", "2", "0", "1", "", "consecutive", "3", "", "", "", "", ""],
        ["e2h", "DATA", "3", "0", "1", "", "first", "4", str(len(dasp)), "", "", "", ""],
        ["e2h", "DATA", "4", "0", "1", "", "consecutive", "4", "", "", "", "DASP",
         "EYEQ_BASE_DIAG_STATUS_MSG"],
        ["e2h", "DATA", "5", "0", "1", "", "single", "", "", str(len(aeb_msg)), "", "DASP",
         "EYEQ_VIS_AEB_INFO_MSG"],
        ["e2h", "DATA", "6", "0", "1", "", "single", "", "", str(len(aeb_msg) - 1), "", "DASP",
         "EYEQ_VIS_AEB_INFO_MSG"],
        ["e2h", "DATA", "7", "0", "1", "", "single", "", "", "3", "", "UNKNOWN", ""],
        ["e2h", "DATA", "8", "0", "1", "", "first", "5", str(len(dasp)), "", "", "", ""],
        ["e2h", "DATA", "9", "0", "1", "", "consecutive", "5", "", "", "", "", ""],
    ]
    experts = [g["_ws.expert.message"] for g in got]
    assert "CRC" in experts[3]
    assert "malformed" in experts[4]
    assert "not a frame kind" in experts[5]
    assert "num_gap" in experts[7]
    assert "NAK" in experts[2] and "CRC_MISMATCH" in experts[2]
    assert "length mismatch" in experts[11]
    assert "unknown message" in experts[12]
    assert "bad_padding" in experts[14]
    assert experts[9] == experts[10] == ""
    assert experts[0] == "eyeq-spi sw=9.0"  # the capture's release, a packet comment
    # a payload of the wrong length: header only
    payload = ["frame.number", "eyeq_spi.dasp.data_id", "eyeq_spi.dasp.counter",
               "eyeq_spi.EYEQ_VIS_AEB_INFO_MSG.timestamp_ms"]
    rows = tshark(capture, tmp_path / "eyeq_spi.lua", payload, tmp_path, two_pass=two_pass)
    data_id = f"0x{codec.cat.message('EYEQ_VIS_AEB_INFO_MSG').data_id:02x}"
    assert rows[10][1:] == [data_id, "9", "4242"]
    assert rows[11][1:] == [data_id, "9", ""]
    # the Python view of the same capture agrees
    with capture.open("rb") as fh:
        records = list(read_pcapng(fh))
    expect = expected_link(records)
    for g, exp in zip(got, expect, strict=True):
        assert {k: g[k] for k in exp if k != "eyeq_spi.nak_reason"} == {
            k: v for k, v in exp.items() if k != "eyeq_spi.nak_reason"}
    assert set(reassemble(records)) == {1, 10, 11, 12, 13}


@needs_tshark
def test_field_names_are_registered(tmp_path: Path) -> None:
    assert TSHARK is not None
    lua = write_lua(tmp_path)
    proc = subprocess.run([TSHARK, "-G", "fields", "-X", f"lua_script:{lua}"],
                          capture_output=True, text=True, timeout=60, check=False,
                          env={**os.environ, "HOME": str(tmp_path)})
    assert proc.returncode == 0, proc.stderr
    assert "Lua: Error" not in proc.stderr, proc.stderr
    names = {line.split("\t")[2] for line in proc.stdout.splitlines()
             if line.startswith("F\t") and "\teyeq_spi\t" in line}
    codec = MessageCodec()
    required = {
        "eyeq_spi.dir", "eyeq_spi.frame_type", "eyeq_spi.num", "eyeq_spi.rsp", "eyeq_spi.crc",
        "eyeq_spi.crc_ok", "eyeq_spi.nak_reason", "eyeq_spi.transport",
        "eyeq_spi.transfer_id", "eyeq_spi.total", "eyeq_spi.size", "eyeq_spi.bad_length",
        "eyeq_spi.mesp.service", "eyeq_spi.mesp.function", "eyeq_spi.mesp.tag",
        "eyeq_spi.mesp.counter", "eyeq_spi.mesp.reply", "eyeq_spi.mesp.ret",
        "eyeq_spi.dasp.data_id", "eyeq_spi.dasp.counter",
        *all_member_fields(codec), *mesp_field_names(codec).values(),
    }
    assert required <= names, sorted(required - names)[:20]


# -- test: trees that are not shown (summary lines, -q, filters) ----------------------------------
def filtered_frames(capture: Path, lua: Path, home: Path, display_filter: str,
                    two_pass: bool = False) -> list[int]:
    """Frame numbers tshark keeps for ``display_filter`` with summary lines: the dissector gets
    a tree that will not be shown, in which only the filter's fields are referenced."""
    assert TSHARK is not None
    cmd = [TSHARK, "-r", str(capture), "-X", f"lua_script:{lua}", "-Y", display_filter]
    if two_pass:
        cmd.append("-2")
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False,
                          env={**os.environ, "HOME": str(home)})
    assert proc.returncode == 0, proc.stderr
    assert "Lua: Error" not in proc.stderr, proc.stderr
    return [int(line.split()[0]) for line in proc.stdout.splitlines() if line.strip()]


@needs_tshark
def test_hidden_trees_keep_what_filters_reference(
        tmp_path: Path, demo_capture: tuple[Path, dict[str, Any]]) -> None:
    """Where the tree is not shown the dissector adds only referenced fields and walks a payload
    only while a member is referenced: every filter still finds what the Python view says."""
    capture, _ = demo_capture
    lua = write_lua(tmp_path)
    with capture.open("rb") as fh:
        records = list(read_pcapng(fh))
    codec = MessageCodec()
    messages = {n: codec.decode(data) for n, data in reassemble(records).items()}
    link = expected_link(records)
    ids: dict[int, set[int]] = {}
    for n, m in messages.items():
        if m.protocol != "MESP":
            flat: dict[str, list[Any]] = {}
            flatten(codec.layout(codec.cat.message(m.name or "")), m.fields, flat)
            for v in flat.get("eyeq_spi.eyeq_vision_object_t.id", []):
                ids.setdefault(int(v), set()).add(n)
    some_id = sorted(ids, key=lambda k: len(ids[k]))[len(ids) // 2]
    multi = {n for n in messages if link[n - 1]["eyeq_spi.transport"] == "consecutive"}
    cases = {
        'eyeq_spi.message == "EYEQ_VIS_OBSTACLES_MSG"':
            {n for n, m in messages.items() if m.name == "EYEQ_VIS_OBSTACLES_MSG"},
        f"eyeq_spi.eyeq_vision_object_t.id == {some_id}": ids[some_id],
        'eyeq_spi.transport == "first"':
            {i for i, row in enumerate(link, 1) if row["eyeq_spi.transport"] == "first"},
        'eyeq_spi.frame_type == "ACK" && eyeq_spi.crc_ok == 1':
            {i for i, row in enumerate(link, 1) if row["eyeq_spi.frame_type"] == "ACK"},
        'eyeq_spi.sw == "9.0" && (eyeq_spi.sw_source == "boot status"'
        ' || eyeq_spi.sw_source == "capture")': set(messages),
        "eyeq_spi.fragment": multi,
        "eyeq_spi.mesp.reply == 1": {n for n, m in messages.items()
                                if m.protocol == "MESP" and m.header.get("reply")},
    }
    assert all(cases.values()), cases
    for display_filter, expect in cases.items():
        got = filtered_frames(capture, lua, tmp_path, display_filter)
        assert set(got) == expect, (display_filter, sorted(set(got) ^ expect)[:10])
    # a second pass (tshark -2) reads what the first pass stored
    display_filter = f"eyeq_spi.eyeq_vision_object_t.id == {some_id}"
    assert set(filtered_frames(capture, lua, tmp_path, display_filter, True)) == ids[some_id]


def test_one_field_per_member_across_releases() -> None:
    """Releases that lay a member out differently share its filter name: the widest integer
    type; a mask or enum only where all agree (the row then computes or labels the value)."""
    from eyeq_spi.wireshark.lua_app import MemberField, merge

    old = MemberField("uint8", "x", "uint8, bits 0-5", 'E["a"]', 0x3F)
    new = MemberField("uint16", "x", "uint16", None, None)
    merged = merge("s.x", [old, new])
    assert (merged.ctor, merged.vs, merged.mask, merged.desc) == ("uint16", None, None, "uint16")
    assert merge("s.x", [old, old]) == old
    with pytest.raises(SpecError, match="cannot share"):
        merge("s.x", [old, MemberField("float", "x", "real32")])
    lua = generate_lua()
    # a member whose mask differs between releases: computed from its container in that layout
    assert "eyeq_spi.host_vehicle_state_t.vehicleYawRateValidity" in lua
    assert re.search(r'F\["host_vehicle_state_t\.vehicleYawRateValidity"\], false, '
                     r'"vehicleYawRateValidity", nil, \{\d+, (0x[0-9A-F]+|\d+)\}', lua)
