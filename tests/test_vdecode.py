"""The vectorised decoder (codec/vdecode.py) and the generated E2E verifier against the exact
codec: every DASP message at every SW release, value for value and error for error."""

from __future__ import annotations

import math
import struct
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eyeq_spi.codec.e2e import E2EState, protect, verify, verify_reference
from eyeq_spi.codec.layout import Layout
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.codec.vdecode import crc_rows, vec_layout
from eyeq_spi.crc import crc16
from eyeq_spi.dissect.engine import _check_enums
from eyeq_spi.dissect.output import flatten
from eyeq_spi.spec.catalog import catalog
from tests.strategies import layout_values

CAT = catalog()
SETTINGS = settings(max_examples=4, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.large_base_example])


def _signature(lay: Layout) -> str:
    inner = ",".join(_signature(c) for c in lay.children.values())
    return f"{lay.name}:{lay.variant}({inner})"


def _cases() -> list[tuple[str, str]]:
    """(message, SW) for every DASP message and release, one per distinct layout."""
    seen: set[tuple[str, str]] = set()
    out: list[tuple[str, str]] = []
    for sw in CAT.sw_versions:
        codec = MessageCodec(sw)
        for msg in CAT.messages:
            if msg.protocol != "DASP" or not msg.exists_in(sw):
                continue
            key = (msg.name, _signature(codec.layout(msg)))
            if key not in seen:
                seen.add(key)
                out.append((msg.name, sw))
    return out


CASES = _cases()
_CODECS: dict[str, MessageCodec] = {}


def _codec(sw: str) -> MessageCodec:
    if sw not in _CODECS:
        _CODECS[sw] = MessageCodec(sw)
    return _CODECS[sw]


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return bool(a == b) and type(a) is type(b)


def test_every_release_and_dasp_message_is_covered() -> None:
    names = {m for m, _ in CASES}
    assert names == {m.name for m in CAT.messages if m.protocol == "DASP"}
    assert {sw for _, sw in CASES} >= {"sw9"}


def test_crc_table_agrees_with_crc16_on_every_length() -> None:
    rng = np.random.default_rng(5)
    for n in range(0, 70):
        g = rng.integers(0, 256, (4, n), np.uint8)
        assert crc_rows(g).tolist() == [crc16(r.tobytes()) for r in g]


@pytest.mark.parametrize(("name", "sw"), CASES)
def test_vectorised_decode_agrees_with_the_exact_codec(name: str, sw: str) -> None:
    codec = _codec(sw)
    msg = codec.message(name)
    lay = codec.layout(msg)
    vl = vec_layout(lay, codec.cat)

    @SETTINGS
    @given(st.data())
    def check(data: st.DataObject) -> None:
        rows = data.draw(st.integers(1, 6))
        # big layouts: one drawn value for every row (the rows still differ in counters,
        # CRCs and the mutations below)
        kinds = 1 if lay.size > 600 else 2
        values = [data.draw(layout_values(CAT, lay)) for _ in range(kinds)]
        tx = E2EState()
        bufs = []
        for i in range(rows):
            buf = bytearray(lay.build(values[i % kinds]))
            protect(buf, lay, tx)
            if lay.crc_plan and data.draw(st.integers(0, 5)) == 0:
                for p in lay.crc_plan:  # a counter jump: skip one step of every counter
                    k = (lay.name, f"{p.path}#{p.field}")
                    if k in tx.sent:
                        tx.sent[k] += 1
            bufs.append(buf)
        # bad enums (CRCs recomputed so the enum check runs) and flipped bytes (bad CRCs)
        for e in vl.enums[:: max(1, len(vl.enums) // 3)]:
            if data.draw(st.integers(0, 3)) == 0:
                r = data.draw(st.integers(0, rows - 1))
                f = vl.dtype.fields[e.leaf.field]
                off, dt = f[1], f[0]
                bad = next(x for x in range(256) if x not in set(e.values.tolist()))
                old = int.from_bytes(bufs[r][off : off + dt.itemsize], "little")
                mask = e.leaf.mask if e.leaf.mask is not None else (1 << (8 * dt.itemsize)) - 1
                new = (old & ~(mask << e.leaf.shift)) | ((bad & mask) << e.leaf.shift)
                if bad & mask == bad:
                    bufs[r][off : off + dt.itemsize] = new.to_bytes(dt.itemsize, "little")
                    protect(bufs[r], lay, None)
        for _ in range(data.draw(st.integers(0, 3))):
            r = data.draw(st.integers(0, rows - 1))
            o = data.draw(st.integers(0, lay.size - 1))
            bufs[r][o] ^= data.draw(st.integers(1, 255))
        seen0 = {} if data.draw(st.booleans()) else {
            (lay.name, f"{p.path}#{p.field}"): data.draw(st.integers(0, 255))
            for p in lay.crc_plan if p.counter_offset is not None}
        exact_state = E2EState(seen=dict(seen0))
        vec_state = E2EState(seen=dict(seen0))
        arr = np.frombuffer(b"".join(bytes(b) for b in bufs), np.uint8).reshape(rows, lay.size)
        verrs = vl.verify(arr, vec_state)
        enum_rows = np.array([not e for e in verrs], bool)
        venums = vl.enum_errors(arr, name, enum_rows)
        cols = vl.columns(arr)
        for r, buf in enumerate(bufs):
            wire = bytes([0x65, msg.data_id, r, 0]) + bytes(buf)
            out = codec.decode(wire, exact_state)
            assert out.errors == verrs[r]
            enum_errs: list[str] = []
            if not out.errors:
                _check_enums(codec, lay, out.fields, name, enum_errs)
            assert enum_errs[:10] == venums.get(r, [])
            flat = flatten(out.fields)
            assert list(flat) == list(cols)
            for k, v in flat.items():
                assert _same(cols[k][r].item(), v), (k, cols[k][r], v)
        assert (exact_state.seen, exact_state.crc_errors, exact_state.counter_errors) == (
            vec_state.seen, vec_state.crc_errors, vec_state.counter_errors)

    check()


@pytest.mark.parametrize(("name", "sw"), [c for c in CASES
                                          if _codec(c[1]).layout(
                                              _codec(c[1]).message(c[0])).crc_plan])
def test_generated_verifier_agrees_with_the_reference_loop(name: str, sw: str) -> None:
    codec = _codec(sw)
    lay = codec.layout(codec.message(name))

    @SETTINGS
    @given(st.binary(min_size=lay.size, max_size=lay.size), st.booleans(),
           st.integers(0, 255))
    def check(data: bytes, with_state: bool, last: int) -> None:
        buf = bytearray(data)
        if last % 2:
            protect(buf, lay, None)  # good CRCs, counters as drawn
        a = E2EState(seen={(lay.name, f"{p.path}#{p.field}"): last for p in lay.crc_plan})
        b = E2EState(seen=dict(a.seen))
        assert verify(bytes(buf), lay, a if with_state else None) == verify_reference(
            bytes(buf), lay, b if with_state else None)
        assert (a.seen, a.crc_errors, a.counter_errors) == (b.seen, b.crc_errors,
                                                           b.counter_errors)

    check()


def test_float_columns_keep_binary32_values() -> None:
    codec = _codec("sw9")
    lay = codec.layout(codec.message("EYEQ_VIS_OBSTACLES_MSG"))
    vl = vec_layout(lay, codec.cat)
    arr = np.zeros((1, lay.size), np.uint8)
    leaf = next(x for x in vl.leaves if x.type == "real32")
    off = vl.dtype.fields[leaf.field][1]
    arr[0, off : off + 4] = np.frombuffer(struct.pack("<f", 0.1), np.uint8)
    assert vl.columns(arr)[leaf.name][0].item() == struct.unpack("<f", struct.pack("<f", 0.1))[0]
