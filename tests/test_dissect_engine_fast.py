"""The fast path agrees with the exact engine record for record, on every test capture:
demo captures, hand-built faults, hypothesis-mutated captures (CRC errors, gaps, duplicates,
resets, aborts, wrong lengths, late frames, cut starts and ends), at several chunk sizes."""

from __future__ import annotations

import io
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eyeq_spi.capture.pcapng_fast import chunks_from_transfers, pcapng_chunks
from eyeq_spi.capture.pcapng_io import CaptureWriter, Transfer, read_pcapng
from eyeq_spi.cli import main
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect import engine
from eyeq_spi.dissect import engine_fast as batch
from eyeq_spi.dissect.engine_fast_frames import FrameBlock, frame_arrays
from eyeq_spi.errors import InputError
from eyeq_spi.link.frame import FrameCodec, NakReason
from eyeq_spi.transport.segment import segment

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

FC = FrameCodec()
MC = MessageCodec()
Rec = tuple[str, float, bytes]


def dasp(name: str, counter: int, e2e: E2EState) -> bytes:
    return MC.encode_dasp(name, MC.layout(MC.message(name)).zero_values(), counter, e2e)


class Wire:
    """Both channels of a synthetic capture: each message segmented into DATA frames 0.3 ms
    apart, each ACKed on the other channel 0.1 ms later."""

    def __init__(self, t0: float = 0.0) -> None:
        self.out: list[Rec] = []
        self.t = t0
        self.num = {"h2e": 0, "e2h": 0}
        self.tid = {"h2e": 0, "e2h": 0}

    def send(self, d: str, msg: bytes) -> None:
        parts = segment(msg, self.tid[d])
        if len(parts) > 1:
            self.tid[d] = (self.tid[d] + 1) % 256
        other = "e2h" if d == "h2e" else "h2e"
        for p in parts:
            self.out.append((d, round(self.t, 6), FC.data_frame(self.num[other], self.num[d], p)))
            self.out.append((other, round(self.t + 0.0001, 6), FC.ack(self.num[d])))
            self.num[d] = (self.num[d] + 1) % 4096
            self.t += 0.0003


def synthetic(n_rounds: int = 6, *, t0: float = 0.0) -> list[Rec]:
    """Both channels: DASP singles and 23-frame obstacle messages from the EyeQ, MESP requests
    from the host, every DATA frame ACKed on the other channel."""
    wire = Wire(t0)
    out, send = wire.out, wire.send
    e2e = E2EState()

    for i in range(n_rounds):
        send("e2h", dasp("EYEQ_VIS_FAILSAFE_MSG", i % 256, e2e))
        send("e2h", dasp("EYEQ_VIS_OBSTACLES_MSG", i % 256, e2e))
        send("h2e", MC.mesp.encode_request("GetEyeQExtendedState", i % 256, {}))
        send("e2h", MC.mesp.encode_reply("GetEyeQExtendedState", i % 256, 0,
                                         {"mainState": 2, "subState": 0}))
        for _ in range(3):
            send("h2e", MC.mesp.encode_request("GetEyeQVersions", i % 256, {}))
        wire.t += 0.01
    return out


def records(items: list[Rec]) -> list[Transfer]:
    return [Transfer(t, d, w) for d, t, w in items]


def agree(items: list[Rec] | list[Transfer], chunk: int = 1 << 15) -> list[dict[str, Any]]:
    recs = [r if isinstance(r, Transfer) else Transfer(r[1], r[0], r[2]) for r in items]
    want = list(engine.iter_records(recs))
    got = list(batch.iter_records(chunks_from_transfers(recs, chunk)))
    for i, (a, b) in enumerate(zip(want, got, strict=False)):
        assert a == b, f"record {i}:\n exact {json.dumps(a)[:400]}\n batch {json.dumps(b)[:400]}"
    assert len(want) == len(got)
    return want


@pytest.fixture(scope="module")
def demo_items(tmp_path_factory: pytest.TempPathFactory) -> list[Transfer]:
    path = tmp_path_factory.mktemp("demo") / "demo.pcapng"
    assert main(["demo", "--virtual-time", "--duration", "1.5", "--objects", "15",
                 "--capture", str(path)]) == 0
    with open(path, "rb") as fh:
        return list(read_pcapng(fh))


# -- capture reader ---------------------------------------------------------------------------
def _pcapng(items: list[Rec], path: Path) -> Path:
    with CaptureWriter(path) as w:
        for d, t, wire in items:
            w.write(d, t, wire)
    return path


def _rows(chunks: Any) -> list[Transfer]:
    return [c.transfer(i) for c in chunks for i in range(len(c))]


def test_fast_pcapng_reader_matches_python_pcapng(tmp_path: Path) -> None:
    items = synthetic(2)
    items.insert(5, ("h2e", 0.5, bytes(127)))  # wrong lengths keep their bytes
    items.insert(9, ("e2h", 0.6, bytes(range(200))))
    path = _pcapng(items, tmp_path / "c.pcapng")
    with open(path, "rb") as fh:
        want = list(read_pcapng(fh))
    for chunk in (1, 7, 1 << 15):
        with open(path, "rb") as fh:
            assert _rows(pcapng_chunks(fh, chunk)) == want


def test_fast_reader_errors_after_the_good_records(tmp_path: Path) -> None:
    path = _pcapng(synthetic(1), tmp_path / "c.pcapng")
    data = path.read_bytes()
    got: list[Transfer] = []
    with pytest.raises(InputError):
        for c in pcapng_chunks(io.BytesIO(data[:-77]), 4):
            got += _rows([c])
    with open(path, "rb") as fh:
        assert got == list(read_pcapng(fh))[: len(got)] and got
    with pytest.raises(InputError):
        list(pcapng_chunks(io.BytesIO(b"\x0a\x0d\x0d\x0a" + b"\xff" * 50)))


def test_frame_arrays_match_the_frame_codec() -> None:
    rng = np.random.default_rng(5)
    rows = [bytes(rng.integers(0, 256, 128, np.uint8)) for _ in range(200)]
    rows += [FC.ack(7), FC.nak(9, NakReason.CRC_MISMATCH), FC.data_frame(1, 2, b"\x00\x05hello")]
    fa = frame_arrays(next(chunks_from_transfers([Transfer(None, "e2h", r) for r in rows])), FC, 0,
                      None)
    for i, r in enumerate(rows):
        f = FC.decode(r)
        assert (int(fa.num[i]), int(fa.rsp[i]), int(fa.d[i])) == (f.num, f.rsp, f.d)
        assert bool(fa.crc_ok[i]) == FC.crc_ok(r, f)


# -- agreement --------------------------------------------------------------------------------
@pytest.mark.parametrize("chunk", [1, 5, 64, 1 << 15])
def test_clean_synthetic_capture(chunk: int) -> None:
    recs = agree(synthetic(), chunk)
    assert sum(r["kind"] == "message" for r in recs) == 6 * 7


def test_demo_capture_agrees(demo_items: list[Transfer]) -> None:
    for chunk in (333, 1 << 15):
        agree(demo_items, chunk)


def _mutations() -> dict[str, Callable[[list[Rec], int], list[Rec]]]:
    def flip(items: list[Rec], i: int) -> list[Rec]:
        d, t, w = items[i]
        return [*items[:i], (d, t, w[:40] + bytes([w[40] ^ 1]) + w[41:]), *items[i + 1:]]

    def drop(items: list[Rec], i: int) -> list[Rec]:
        return items[:i] + items[i + 1:]

    def dup(items: list[Rec], i: int) -> list[Rec]:
        return [*items[: i + 1], items[i], *items[i + 1:]]

    def swap(items: list[Rec], i: int) -> list[Rec]:
        j = min(i + 2, len(items) - 1)
        out = list(items)
        out[i], out[j] = out[j], out[i]
        return out

    def short(items: list[Rec], i: int) -> list[Rec]:
        d, t, w = items[i]
        return [*items[:i], (d, t, w[:100]), *items[i + 1:]]

    def late(items: list[Rec], i: int) -> list[Rec]:  # a 30 ms stall: reassembly timeouts
        return items[:i] + [(d, t + 0.03, w) for d, t, w in items[i:]]

    def reset(items: list[Rec], i: int) -> list[Rec]:  # the EyeQ's driver starts over at NUM 0
        d = "e2h"
        out = list(items[:i])
        num = 0
        for dd, t, w in items[i:]:
            if dd == d and len(w) == 128 and w[0] == 0x08:
                f = FC.decode(w)
                w = FC.data_frame(0 if num == 0 else f.rsp, num, f.data)
                num += 1
            out.append((dd, t, w))
        return out

    def header(items: list[Rec], i: int) -> list[Rec]:  # a bad transport type, CRC fixed
        d, t, w = items[i]
        if len(w) != 128 or FC.decode(w).d != 0x8:
            return items
        f = FC.decode(w)
        return [*items[:i], (d, t, FC.data_frame(f.rsp, f.num, b"\x07" + f.data[1:])),
                *items[i + 1:]]

    def padding(items: list[Rec], i: int) -> list[Rec]:  # T6a: a non-zero byte in the
        # padding of a transfer's last consecutive frame (the data field's last byte), CRC fixed
        def data(k: int) -> bool:
            return len(items[k][2]) == 128 and items[k][2][0] == 0x08

        for k in range(i, len(items)):
            d, t, w = items[k]
            if not (data(k) and w[6] == 0x02):
                continue
            nxt = next((j for j in range(k + 1, len(items)) if items[j][0] == d and data(j)),
                       None)
            if nxt is None or items[nxt][2][6] != 0x02:  # the transfer's last frame
                f = FC.decode(w)
                w = FC.data_frame(f.rsp, f.num, f.data[:-1] + b"\xab")
                return [*items[:k], (d, t, w), *items[k + 1:]]
        return items

    def cut_start(items: list[Rec], i: int) -> list[Rec]:
        return items[i:]

    def cut_end(items: list[Rec], i: int) -> list[Rec]:
        return items[: max(i, 1)]

    def notime(items: list[Rec], i: int) -> list[Rec]:
        return [(d, float("nan") if k >= i else t, w) for k, (d, t, w) in enumerate(items)]

    return {f.__name__: f for f in (flip, drop, dup, swap, short, late, reset, header,
                                    padding, cut_start, cut_end, notime)}


MUTATIONS = _mutations()
BASE = synthetic(8)


def _as_records(items: list[Rec]) -> list[Transfer]:
    return [Transfer(None if t != t else t, d, w) for d, t, w in items]


@pytest.mark.parametrize("name", sorted(MUTATIONS))
def test_each_fault_agrees(name: str) -> None:
    for i, chunk in ((3, 1 << 15), (77, 16), (150, 1 << 15), (len(BASE) - 5, 16)):
        agree(_as_records(MUTATIONS[name](BASE, min(i, len(BASE) - 1))), chunk)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(sorted(MUTATIONS)), st.integers(0, 10**6)),
                min_size=1, max_size=5),
       st.sampled_from([3, 17, 64, 1 << 15]))
def test_hypothesis_faults_agree(ops: list[tuple[str, int]], chunk: int) -> None:
    items = BASE
    for name, where in ops:
        if len(items) < 2:
            break
        items = MUTATIONS[name](items, where % len(items))
    agree(_as_records(items), chunk)


def test_faults_in_a_demo_capture_agree(demo_items: list[Transfer]) -> None:
    items = [(r.direction or "e2h", r.time or 0.0, r.data) for r in demo_items]
    rng = np.random.default_rng(11)
    for name in sorted(MUTATIONS):
        if name in ("cut_start", "cut_end", "notime"):
            continue
        for _ in range(3):
            items = MUTATIONS[name](items, int(rng.integers(len(items) // 4, len(items) - 2)))
    agree(_as_records(items), 1000)


def test_batch_really_skips_the_engine_on_clean_traffic() -> None:
    """Most frames of a clean capture come out of FrameBlocks, not the engine."""
    items = list(batch.iter_items(chunks_from_transfers(_as_records(synthetic(20)))))
    block_frames = sum(b.hi - b.lo for b in items if isinstance(b, FrameBlock))
    exact_frames = sum(1 for r in items if isinstance(r, dict) and r["kind"] == "frame")
    assert block_frames > 10 * exact_frames


def test_span_state_survives_single_frames_after_a_multi_frame_transfer() -> None:
    """The receiver's transport state (L9: a first frame was seen) comes back after a long span of
    single frames that followed the span's only multi-frame transfer."""
    e2e = E2EState()
    items: list[Rec] = []
    num = 0
    t = 0.0

    def put(payload: bytes, *, flip: bool = False) -> None:
        nonlocal num, t
        w = bytearray(FC.data_frame(0, num, payload))
        if flip:
            w[50] ^= 0xFF
        items.append(("e2h", round(t, 6), bytes(w)))
        num += 1
        t += 0.0003

    single = segment(MC.mesp.encode_reply("GetEyeQExtendedState", 1, 0,
                                          {"mainState": 2, "subState": 0}), 0)[0]
    for _ in range(3):
        put(single)
    for p in segment(dasp("EYEQ_VIS_OBSTACLES_MSG", 0, e2e), 9):
        put(p)
    for _ in range(20):
        put(single)
    put(single, flip=True)
    put(bytes([2, 77]) + bytes(120))  # a consecutive frame of no open transfer
    recs = agree(_as_records(items))
    kinds = [(r.get("type"), r.get("reason")) for r in recs if r["kind"] == "event"]
    assert ("transfer_aborted", "no_open_transfer") in kinds
