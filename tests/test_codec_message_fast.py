"""The vectorised decoder (codec/message_fast.py) and the generated E2E verifier against the exact
codec: every DASP message at every SW release, value for value and error for error."""

from __future__ import annotations

import math
import struct
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from eyeq_spi.capture.pcapng_fast import chunks_from_transfers
from eyeq_spi.capture.pcapng_io import CaptureWriter, Transfer
from eyeq_spi.catalog.messages import catalog
from eyeq_spi.cli import main
from eyeq_spi.codec.e2e import E2EState, protect
from eyeq_spi.codec.layout import Layout
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.codec.message_fast import crc_rows, vec_layout
from eyeq_spi.crc import crc16
from eyeq_spi.dissect import engine, pipeline, pipeline_fast
from eyeq_spi.dissect import engine_fast as batch
from eyeq_spi.dissect.engine import _check_enums
from eyeq_spi.dissect.engine_fast_frames import FrameBlock
from eyeq_spi.dissect.output import TableWriter, flatten
from eyeq_spi.dissect.stats import Stats
from eyeq_spi.link.frame import FrameCodec
from eyeq_spi.transport.segment import segment
from tests.strategies import layout_values

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

CAT = catalog()
FC = FrameCodec()
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


def test_float_columns_keep_binary32_values() -> None:
    codec = _codec("sw9")
    lay = codec.layout(codec.message("EYEQ_VIS_OBSTACLES_MSG"))
    vl = vec_layout(lay, codec.cat)
    arr = np.zeros((1, lay.size), np.uint8)
    leaf = next(x for x in vl.leaves if x.type == "real32")
    off = vl.dtype.fields[leaf.field][1]
    arr[0, off : off + 4] = np.frombuffer(struct.pack("<f", 0.1), np.uint8)
    assert vl.columns(arr)[leaf.name][0].item() == struct.unpack("<f", struct.pack("<f", 0.1))[0]


# -- the fast path's span messages (dissect/engine_fast_messages.py) ---------------------
def _capture(faults: list[tuple[int, int]]) -> list[Transfer]:
    """e2h DASP traffic (failsafe, obstacles, SRP, light sensor, timesync) in single and
    multi-frame transfers, each data ID's counters and E2E stepping; ``faults`` (message index,
    kind) break messages at the application layer only (the link frames stay good)."""
    codec = MessageCodec()
    tx = E2EState()
    names = ["EYEQ_VIS_FAILSAFE_MSG", "EYEQ_VIS_OBSTACLES_MSG", "EYEQ_VIS_SRP_MSG",
             "EYEQ_VIS_LIGHT_SENSOR_DATA_MSG", "EYEQ_TIMESYNC_MSG"]
    zero = {n: codec.layout(codec.message(n)).zero_values() for n in names}
    diag = codec.layout(codec.message("EYEQ_DIAGNOSTIC_MSG")).zero_values()
    kinds = dict(faults)
    out: list[Transfer] = []
    num, tid, t = 0, 0, 0.0
    counters = dict.fromkeys(names, 0)
    for i in range(40):
        name = names[i % len(names)]
        msg = codec.message(name)
        hdr = 4
        if i % 8 == 7:  # a 0x41 diagnostic message: one ID byte, no E2E, no counter
            msg = codec.message("EYEQ_DIAGNOSTIC_MSG")
            hdr, name = 1, msg.name
            wire = bytearray(codec.encode_other("DIAG", diag))
        else:
            wire = bytearray(codec.encode_dasp(name, zero[name], counters[name] % 256, tx))
            counters[name] += 1
        kind = kinds.get(i)
        if hdr == 1 and kind not in (4, 5):
            kind = None
        if kind == 1:  # an E2E CRC broken
            lay = codec.layout(msg)
            if lay.crc_plan:
                o = 4 + lay.crc_plan[0].crc_offset
                wire[o] ^= 0x5A
        elif kind == 2:  # a DASP counter gap
            counters[name] += 3
        elif kind == 3:  # reserved byte set
            wire[3] = 0x80
        elif kind == 4:  # an undefined enum value, CRCs made good again
            lay = codec.layout(msg)
            vl = vec_layout(lay, codec.cat)
            if vl.enums:
                e = vl.enums[i % len(vl.enums)]
                off, dt = vl.dtype.fields[e.leaf.field][1], vl.dtype.fields[e.leaf.field][0]
                mask = e.leaf.mask if e.leaf.mask is not None else (1 << (8 * dt.itemsize)) - 1
                bad = next((x for x in range(mask + 1) if x not in set(e.values.tolist())),
                           None)
                if bad is not None:
                    o = hdr + off
                    old = int.from_bytes(wire[o : o + dt.itemsize], "little")
                    new = (old & ~(mask << e.leaf.shift)) | (bad << e.leaf.shift)
                    wire[o : o + dt.itemsize] = new.to_bytes(dt.itemsize, "little")
                    payload = bytearray(wire[hdr:])
                    protect(payload, lay, None)
                    wire[hdr:] = payload
        elif kind == 5:  # wrong length
            wire = wire[:-1]
        elif kind == 6:  # an E2E rolling counter jump
            lay = codec.layout(msg)
            for p in lay.crc_plan:
                k = (lay.name, f"{p.path}#{p.field}")
                if k in tx.sent:
                    tx.sent[k] += 2
        elif kind == 7:  # an unknown data ID
            wire[1] = 0xFE
        for part in segment(bytes(wire), tid):
            out.append(Transfer(round(t, 6), "e2h", FC.data_frame(0, num, part)))
            num = (num + 1) % 4096
            t += 0.0003
        tid = (tid + 1) % 256
        t += 0.002
    return out


@settings(max_examples=15, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 39), st.integers(1, 7)), max_size=6),
       st.sampled_from([7, 64, 1 << 15]))
def test_span_messages_agree_with_the_engine_under_application_faults(
        faults: list[tuple[int, int]], chunk: int) -> None:
    recs = _capture(faults)
    want = list(engine.iter_records(recs))
    got = list(batch.iter_records(chunks_from_transfers(recs, chunk)))
    assert got == want
    lean = list(batch.iter_records(chunks_from_transfers(recs, chunk), fields="none"))
    assert len(lean) == len(want)
    for a, b in zip(want, lean, strict=True):
        if b["kind"] == "message" and b["protocol"] != "MESP" and not b["fields"]:
            a = {**a, "fields": {}}
        assert a == b


def test_application_faults_reach_the_vectorised_groups() -> None:
    """The faults above are judged by engine_fast_messages' groups, not only by the exact
    fallback."""
    recs = _capture([(1, 1), (6, 6), (11, 4), (13, 4), (16, 3), (22, 2)])
    items = list(batch.iter_items(chunks_from_transfers(recs, 1 << 15)))
    msgs = [m for b in items if isinstance(b, FrameBlock) for _, m in b.messages]
    errors = [e for m in msgs for e in m["errors"]]
    for needle in ("E2E CRC mismatch", "E2E counter jump", "bad enum value", "reserved byte",
                   "DASP counter gap"):
        assert any(needle in e for e in errors), needle
    assert want_equal(recs)


def want_equal(recs: list[Transfer]) -> bool:
    return list(engine.iter_records(recs)) == list(batch.iter_records(
        chunks_from_transfers(recs, 1 << 15)))


def test_no_two_dasp_messages_share_a_layout() -> None:
    """engine_fast_messages judges (direction, data ID) groups independently: E2E counters are
    keyed by layout, so that needs one layout per data ID in every release."""
    for sw in CAT.sw_versions:
        payloads = [m.payload for m in CAT.messages if m.protocol == "DASP" and m.exists_in(sw)]
        assert len(payloads) == len(set(payloads)), sw


def _tables(tmp: Path, fmt: str, recs: list[Transfer], chunk: int | None) -> Path:
    """The tables of the exact engine (chunk None) or of the fast path in columns mode."""
    out = tmp / f"{fmt}-{chunk}"
    w = TableWriter(str(out), fmt, batch=3)  # small batches: column and dict rows interleave
    if chunk is None:
        for r in engine.iter_records(recs):
            w.write(r)
    else:
        for item in batch.iter_items(chunks_from_transfers(recs, chunk), fields="columns"):
            if isinstance(item, FrameBlock):
                pipeline_fast.consume(item, lambda r: True, True, Stats(CAT), [w])
            else:
                w.write(item)
    w.close()
    return out


@settings(max_examples=6, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 39), st.integers(1, 7)), max_size=4),
       st.sampled_from([7, 1 << 15]))
# a damaged first message without fields, then clean ones as a column batch: one part, as the
# reference writes them (the columns of a row group are those of all its rows)
@example(faults=[(0, 5)], chunk=1 << 15)
def test_table_columns_agree_with_the_exact_rows(faults: list[tuple[int, int]],
                                                 chunk: int) -> None:
    pq = pytest.importorskip("pyarrow.parquet", reason="--parquet needs pyarrow (extra)")
    recs = _capture(faults)
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp)
        want, got = _tables(base, "csv", recs, None), _tables(base, "csv", recs, chunk)
        names = sorted(p.name for p in want.iterdir())
        assert names == sorted(p.name for p in got.iterdir())
        for n in names:
            assert (want / n).read_bytes() == (got / n).read_bytes(), n
        want, got = _tables(base, "parquet", recs, None), _tables(base, "parquet", recs, chunk)
        for n in sorted(p.name for p in want.iterdir()):
            a, b = pq.read_table(want / n), pq.read_table(got / n)
            assert a.schema.equals(b.schema) and a.equals(b), n


def test_columns_mode_really_writes_columns() -> None:
    recs = _capture([])
    items = list(batch.iter_items(chunks_from_transfers(recs, 1 << 15), fields="columns"))
    groups = [g for b in items if isinstance(b, FrameBlock) for g in b.tables]
    assert {g.name for g in groups} >= {"EYEQ_VIS_OBSTACLES_MSG", "EYEQ_VIS_FAILSAFE_MSG"}
    assert pipeline.fields_mode([], True) == "none"
    assert pipeline.fields_mode([], False) == "none"
    assert pipeline.fields_mode([TableWriter.__new__(TableWriter)], True) == "columns"
    assert pipeline.fields_mode([TableWriter.__new__(TableWriter)], False) == "dict"


def test_jobs_tables_are_the_serial_tables(tmp_path: Path) -> None:
    """--jobs workers send column groups to the parent: same CSV as a serial run."""
    files = []
    for k, faults in enumerate(([], [(4, 1), (9, 4)])):
        path = tmp_path / f"c{k}.pcapng"
        with CaptureWriter(path) as w:
            for r in _capture(faults):
                w.write(r.direction, r.time, r.data)
        files.append(str(path))
    assert main(["dissect", *files, "--csv", str(tmp_path / "serial")]) in (0, 1)
    assert main(["dissect", "--jobs", "2", *files, "--csv", str(tmp_path / "jobs")]) in (0, 1)
    names = sorted(p.name for p in (tmp_path / "serial").iterdir())
    assert "EYEQ_VIS_OBSTACLES_MSG.csv" in names
    assert names == sorted(p.name for p in (tmp_path / "jobs").iterdir())
    for n in names:
        assert (tmp_path / "serial" / n).read_bytes() == (tmp_path / "jobs" / n).read_bytes()
