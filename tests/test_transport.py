"""Transport: segmentation/reassembly round trips, limits and aborts (T1-T6)."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eyeq_spi.errors import LocalProtocolError
from eyeq_spi.link import LinkConfig, NakReason
from eyeq_spi.link.events import FrameRejected
from eyeq_spi.link.frame import FrameCodec, FrameKind
from eyeq_spi.transport import (
    MessageReceived,
    MessageSendFailed,
    MessageSent,
    TransferAborted,
    TransportConnection,
    segment,
)
from tests.conftest import Pair

codec = FrameCodec()


def of(events: list[Any], kind: type) -> list[Any]:
    return [e for e in events if isinstance(e, kind)]


def new_pair() -> Pair:
    return Pair(
        TransportConnection(LinkConfig(role="host")), TransportConnection(LinkConfig(role="eyeq"))
    )


def transport_bytes(pair: Pair, side: str) -> list[bytes]:
    """The data fields of the DATA frames ``side`` sent, in wire order."""
    out = []
    for _, who, t in pair.log:
        f = codec.decode(t)
        if who == side and f.kind is FrameKind.DATA:
            out.append(f.data)
    return out


def test_single_first_and_consecutive_layouts() -> None:
    assert segment(b"abc", 9) == [b"\x00\x03abc"]
    msg = bytes(range(256)) * 2  # 512 bytes
    parts = segment(msg, 7)
    assert parts[0][:6] == b"\x01\x07" + (512).to_bytes(4, "little")
    assert parts[0][6:] == msg[:116]
    assert [p[:2] for p in parts[1:]] == [b"\x02\x07"] * 4
    assert b"".join(p[2:] for p in parts[1:]) == msg[116:]
    assert len(parts) == 5
    assert len(segment(bytes(120), 0)) == 1 and len(segment(bytes(121), 0)) == 2


@pytest.mark.parametrize("size", [0, 8192])
def test_message_size_limits_on_send(size: int) -> None:
    with pytest.raises(LocalProtocolError):
        segment(bytes(size), 0)


@given(st.binary(min_size=1, max_size=8191))
def test_any_message_up_to_8191_round_trips_eyeq_to_host(msg: bytes) -> None:
    pair = new_pair()
    pair.sides["eyeq"].send(msg, 0.0)
    pair.run(1.0)
    got = of(pair.events("host"), MessageReceived)
    assert [g.data for g in got] == [msg]
    assert len(got[0].frames) == len(segment(msg, 0))
    assert of(pair.events("eyeq"), MessageSent)


@given(st.binary(min_size=1, max_size=512))
def test_any_message_up_to_512_round_trips_host_to_eyeq(msg: bytes) -> None:
    pair = new_pair()
    pair.sides["host"].send(msg, 0.0)
    pair.run(1.0)
    assert [g.data for g in of(pair.events("eyeq"), MessageReceived)] == [msg]


@pytest.mark.parametrize("size", [1, 116, 117, 120, 121, 236, 237, 4096, 8190, 8191])
def test_boundary_sizes_both_directions(size: int) -> None:
    pair = new_pair()
    msg = bytes((i * 7) & 0xFF for i in range(size))
    pair.sides["eyeq"].send(msg, 0.0)
    if size <= 512:
        pair.sides["host"].send(msg, 0.0)
    pair.run(1.0)
    assert [g.data for g in of(pair.events("host"), MessageReceived)] == [msg]
    if size <= 512:
        assert [g.data for g in of(pair.events("eyeq"), MessageReceived)] == [msg]


@given(start=st.integers(240, 255), count=st.integers(1, 30))
def test_transfer_id_wraps_from_255_to_0(start: int, count: int) -> None:
    pair = new_pair()
    pair.sides["eyeq"].reset(transfer_id=start)
    for i in range(count):
        pair.sides["eyeq"].send(bytes([i]) * 200, 0.0)
    pair.run(5.0)
    got = of(pair.events("host"), MessageReceived)
    assert [g.transfer_id for g in got] == [(start + i) % 256 for i in range(count)]
    assert [g.data for g in got] == [bytes([i]) * 200 for i in range(count)]


def test_frames_of_one_message_are_never_interleaved() -> None:
    pair = new_pair()
    host = pair.sides["host"]
    host.send(b"A" * 400, 0.0)
    host.send(b"B" * 10, 0.0)
    host.send(b"C" * 300, 0.0)
    pair.run(1.0)
    kinds = [(d[0], d[1]) for d in transport_bytes(pair, "host")]
    assert kinds == [(1, 0), (2, 0), (2, 0), (2, 0), (0, 10), (1, 1), (2, 1), (2, 1)]
    assert [g.data[:1] for g in of(pair.events("eyeq"), MessageReceived)] == [b"A", b"B", b"C"]


def test_total_above_the_eyeq_limit_is_naked_as_format_error() -> None:
    pair = new_pair()
    pair.sides["host"].send(bytes(513), 0.0)
    pair.run(1.0)
    eyeq = pair.sides["eyeq"]
    assert eyeq.link.counters.formatErrorCounter == 1
    assert eyeq.link.counters.rcvOverflowErrors == 1
    rejected = of(pair.events("eyeq"), FrameRejected)
    assert [(r.nak_reason, r.num) for r in rejected] == [(NakReason.FORMAT_ERROR, 0)]
    failed = of(pair.events("host"), MessageSendFailed)
    assert [(f.message_id, f.reason) for f in failed] == [(0, "nak")]
    # only the first frame went out: the rest of the message was dropped with it
    assert len(transport_bytes(pair, "host")) <= 8


@pytest.mark.parametrize(
    ("data", "why"),
    [
        (b"\x00\x00", "single size 0"),
        (b"\x00\x79", "single size 121"),
        (b"\x01\x00" + (116).to_bytes(4, "little"), "first total 116"),
        (b"\x01\x00" + (8192).to_bytes(4, "little"), "first total 8192"),
        (b"\x03\x00", "transport type 3"),
    ],
)
def test_bad_transport_headers_are_naked_0x011(data: bytes, why: str) -> None:
    host = TransportConnection(LinkConfig(role="host"))
    host.receive_data(codec.data_frame(0, 0, data), 0.0)
    assert host.link.counters.formatErrorCounter == 1, why
    (nak,) = [codec.decode(t) for t in host.data_to_send(0.0)]
    assert (nak.kind, nak.rsp, nak.num) == (FrameKind.NAK, 0, 0x011)
    assert host.link.expected_num == 0  # a rejected frame is not accepted


def feed(conn: TransportConnection, frames: list[tuple[int, bytes]], now: float = 0.0) -> None:
    for num, data in frames:
        conn.receive_data(codec.data_frame(0, num, data), now)


def test_gap_in_num_aborts_the_transfer() -> None:
    host = TransportConnection(LinkConfig(role="host"))
    parts = segment(bytes(range(256)) * 2, 3)
    feed(host, [(0, parts[0]), (1, parts[1]), (3, parts[3])])
    ev = list(iter(host.next_event, None))
    aborted = of(ev, TransferAborted)
    assert [(a.reason, a.transfer_id, a.received, a.total) for a in aborted] == [
        ("num_gap", 3, 236, 512)
    ]
    assert not of(ev, MessageReceived)
    assert host.counters.transferAborts == {"num_gap": 1}


def test_wrong_id_is_naked_and_aborts() -> None:
    host = TransportConnection(LinkConfig(role="host"))
    parts = segment(bytes(300), 3)
    bad = b"\x02\x04" + parts[1][2:]
    feed(host, [(0, parts[0]), (1, bad)])
    ev = list(iter(host.next_event, None))
    assert [a.reason for a in of(ev, TransferAborted)] == ["wrong_id"]
    assert [r.nak_reason for r in of(ev, FrameRejected)] == [NakReason.FORMAT_ERROR]
    assert host.link.counters.formatErrorCounter == 1


def test_consecutive_without_first_frame_is_an_abort_not_an_exception() -> None:
    host = TransportConnection(LinkConfig(role="host"))
    parts = segment(bytes(300), 5)
    feed(host, [(0, parts[1])])
    ev = list(iter(host.next_event, None))
    assert [(a.reason, a.transfer_id) for a in of(ev, TransferAborted)] == [("no_open_transfer", 5)]


def test_silence_of_25_ms_aborts_the_transfer() -> None:
    host = TransportConnection(LinkConfig(role="host"))
    parts = segment(bytes(500), 1)
    feed(host, [(0, parts[0])], now=1.0)
    host.data_to_send(1.0)
    assert host.get_timer() == pytest.approx(1.025)
    host.handle_timer(1.0249)
    assert not of(list(iter(host.next_event, None)), TransferAborted)
    host.handle_timer(1.025)
    assert [a.reason for a in of(list(iter(host.next_event, None)), TransferAborted)] == ["timeout"]


def test_new_first_frame_aborts_the_open_transfer() -> None:
    host = TransportConnection(LinkConfig(role="host"))
    a, b = segment(b"a" * 300, 1), segment(b"b" * 200, 2)
    feed(host, [(0, a[0]), (1, b[0]), (2, b[1])])
    ev = list(iter(host.next_event, None))
    assert [x.reason for x in of(ev, TransferAborted)] == ["new_first_frame"]
    assert [m.data for m in of(ev, MessageReceived)] == [b"b" * 200]


def test_single_frame_inside_a_transfer_is_delivered_and_aborts_it() -> None:
    host = TransportConnection(LinkConfig(role="host"))
    a = segment(b"a" * 300, 1)
    feed(host, [(0, a[0]), (1, segment(b"hi", 0)[0])])
    ev = list(iter(host.next_event, None))
    assert [x.reason for x in of(ev, TransferAborted)] == ["interleaved"]
    assert [m.data for m in of(ev, MessageReceived)] == [b"hi"]


def test_dropped_consecutive_frame_fails_the_message_on_both_sides() -> None:
    pair = new_pair()
    pair.mangle["eyeq"] = lambda i, t: [] if i == 2 else [t]
    pair.sides["eyeq"].send(bytes(600), 0.0)
    pair.sides["eyeq"].send(b"next", 0.0)
    pair.run(1.0)
    hev = pair.events("host")
    assert [a.reason for a in of(hev, TransferAborted)] == ["num_gap"]
    assert pair.sides["host"].counters.framesDiscarded == 2  # frames 4 and 5 of 6
    assert [m.data for m in of(hev, MessageReceived)] == [b"next"]
    eev = pair.events("eyeq")
    assert [(f.message_id, f.reason) for f in of(eev, MessageSendFailed)] == [(0, "ack_timeout")]
    assert [s.message_id for s in of(eev, MessageSent)] == [1]
    assert pair.sides["eyeq"].link.counters.sendFailedErrorCounter == 1
