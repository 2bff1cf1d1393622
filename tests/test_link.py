"""Link layer fault tests on hand-wired connections, checked against exact counters (L5-L8)."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eyeq_spi.link import LinkConfig, LinkConnection, NakReason
from eyeq_spi.link.events import (
    DataReceived,
    DuplicateReceived,
    FrameRejected,
    FramesSkipped,
    Resynchronised,
    SendFailed,
    Sent,
    UnexpectedAck,
)
from eyeq_spi.link.frame import FrameCodec, FrameKind
from tests.conftest import Pair

codec = FrameCodec()


def of(events: list[Any], kind: type) -> list[Any]:
    return [e for e in events if isinstance(e, kind)]


def payload(i: int) -> bytes:
    return bytes([0, 3]) + i.to_bytes(3, "big")


def flip(byte_index: int, bit: int = 0):  # type: ignore[no-untyped-def]
    def mangle(idx: int, t: bytes) -> list[bytes]:
        if idx != 0:
            return [t]
        b = bytearray(t)
        b[byte_index] ^= 1 << bit
        return [bytes(b)]
    return mangle


def nak_frames(pair: Pair, side: str) -> list[tuple[int, int]]:
    out = []
    for _, who, t in pair.log:
        f = codec.decode(t)
        if who == side and f.kind is FrameKind.NAK:
            out.append((f.rsp, f.num))
    return out


def test_clean_exchange_acks_every_frame(link_pair: Pair) -> None:
    host = link_pair.sides["host"]
    for i in range(20):
        host.send(payload(i), tag=i, now=0.0)
    link_pair.run(1.0)
    got = of(link_pair.events("eyeq"), DataReceived)
    assert [e.data[:5] for e in got] == [payload(i) for i in range(20)]
    assert [e.tag for e in of(link_pair.events("host"), Sent)] == list(range(20))
    eyeq = link_pair.sides["eyeq"]
    assert eyeq.counters.framesReceived == 20 and host.counters.framesAcked == 20
    assert host.counters.busyFrames == 0
    assert all(v == 0 for k, v in eyeq.counters.seed_view().items())


@pytest.mark.parametrize(
    ("where", "byte_index"), [("header", 2), ("crc", 4), ("payload", 60)]
)
def test_flipped_bit_is_naked_as_crc_mismatch(link_pair: Pair, where: str, byte_index: int) -> None:
    host, eyeq = link_pair.sides["host"], link_pair.sides["eyeq"]
    link_pair.mangle["host"] = flip(byte_index, 3)
    host.send(payload(1), tag=1, now=0.0)
    link_pair.run(0.1)
    assert eyeq.counters.dataCRCErrorCounter == 1
    assert eyeq.counters.sequenceErrorCounter == 0 and eyeq.counters.formatErrorCounter == 0
    assert nak_frames(link_pair, "eyeq") == [(0, NakReason.CRC_MISMATCH)]
    failed = of(link_pair.events("host"), SendFailed)
    assert [(f.tag, f.reason, f.nak_reason) for f in failed] == [(1, "nak", NakReason.CRC_MISMATCH)]
    assert host.counters.sendFailedErrorCounter == 1
    assert not of(link_pair.events("eyeq"), DataReceived)


def test_flipped_bit_in_an_ack_is_counted_but_never_answered(link_pair: Pair) -> None:
    host = link_pair.sides["host"]
    link_pair.mangle["eyeq"] = flip(5, 1)  # the CRC of the first ACK
    host.send(payload(1), tag=1, now=0.0)
    link_pair.run(0.1)
    assert host.counters.dataCRCErrorCounter == 1
    assert nak_frames(link_pair, "host") == []
    # the ACK was lost, so the frame times out after ackTimeout (L7)
    assert [f.reason for f in of(link_pair.events("host"), SendFailed)] == ["ack_timeout"]


def test_invalid_d_and_r_are_format_errors(link_pair: Pair) -> None:
    eyeq = link_pair.sides["eyeq"]
    from eyeq_spi.link.frame import Frame
    eyeq.receive_data(codec.encode(Frame(0x9, 0, 0, 0)), 0.0)
    eyeq.receive_data(codec.encode(Frame(0x8, 1, 0, 1)), 0.0)
    assert eyeq.counters.formatErrorCounter == 2
    reasons = [e.nak_reason for e in of(link_pair.events("eyeq"), FrameRejected)]
    assert reasons == [NakReason.FORMAT_ERROR, NakReason.FORMAT_ERROR]
    naks = [codec.decode(t) for t in eyeq.data_to_send(1.0)]
    assert [(f.rsp, f.num) for f in naks] == [(0, 0x011), (1, 0x011)]


def test_dropped_frame_is_skipped_and_its_message_fails_on_ack_timeout(link_pair: Pair) -> None:
    host, eyeq = link_pair.sides["host"], link_pair.sides["eyeq"]
    link_pair.mangle["host"] = lambda i, t: [] if i == 1 else [t]
    for i in range(3):
        host.send(payload(i), tag=i, now=0.0)
    link_pair.run(0.1)
    ev = link_pair.events("eyeq")
    assert [e.num for e in of(ev, DataReceived)] == [0, 2]
    assert [(e.expected, e.num, e.count) for e in of(ev, FramesSkipped)] == [(1, 2, 1)]
    assert eyeq.counters.skippedFrames == 1
    hev = link_pair.events("host")
    assert [(f.tag, f.num, f.reason) for f in of(hev, SendFailed)] == [(1, 1, "ack_timeout")]
    assert sorted(e.tag for e in of(hev, Sent)) == [0, 2]
    assert host.counters.sendFailedErrorCounter == 1
    assert eyeq.counters.seed_view()["sequenceErrorCounter"] == 0


def test_duplicated_frame_is_acked_again_and_dropped(link_pair: Pair) -> None:
    host, eyeq = link_pair.sides["host"], link_pair.sides["eyeq"]
    link_pair.mangle["host"] = lambda i, t: [t, t] if i == 0 else [t]
    host.send(payload(0), tag=0, now=0.0)
    link_pair.run(0.1)
    ev = link_pair.events("eyeq")
    assert len(of(ev, DataReceived)) == 1
    assert [e.num for e in of(ev, DuplicateReceived)] == [0]
    assert eyeq.counters.duplicateFrames == 1
    hev = link_pair.events("host")
    assert [e.tag for e in of(hev, Sent)] == [0]
    assert [(e.kind, e.rsp) for e in of(hev, UnexpectedAck)] == [("ACK", 0)]
    assert host.counters.unexpectedAckCounter == 1
    assert eyeq.counters.sequenceErrorCounter == 0


def test_reordered_frame_is_a_late_frame_and_is_naked(link_pair: Pair) -> None:
    """L6a: frame 2 ahead of frame 1 is accepted (1 skipped); 1 then arrives in [E-W, E) but was
    never accepted, so it is a late frame: NAK 0x001 and dropped, and its sender learns that it
    was lost (before L6a it was ACKed as a duplicate although it was never delivered)."""
    host, eyeq = link_pair.sides["host"], link_pair.sides["eyeq"]
    held: list[bytes] = []

    def swap(i: int, t: bytes) -> list[bytes]:
        if i == 1:
            held.append(t)
            return []
        if i == 2:
            return [t, *held]
        return [t]

    link_pair.mangle["host"] = swap
    for i in range(3):
        host.send(payload(i), tag=i, now=0.0)
    link_pair.run(0.1)
    ev = link_pair.events("eyeq")
    assert [e.num for e in of(ev, DataReceived)] == [0, 2]
    assert of(ev, DuplicateReceived) == []
    c = eyeq.counters
    counts = (c.skippedFrames, c.lateFrames, c.duplicateFrames, c.sequenceErrorCounter)
    assert counts == (1, 1, 0, 1)
    assert nak_frames(link_pair, "eyeq") == [(1, NakReason.OUT_OF_WINDOW)]
    hev = link_pair.events("host")
    assert sorted(e.tag for e in of(hev, Sent)) == [0, 2]
    assert [(f.tag, f.reason) for f in of(hev, SendFailed)] == [(1, "nak")]


def test_true_duplicate_is_acked_and_dropped_but_same_num_other_bytes_is_a_reset() -> None:
    """L6a: byte-identical repeat -> duplicate; same NUM with other bytes -> the peer reset:
    resynchronise and accept."""
    rx = LinkConnection(LinkConfig(role="eyeq"))
    frames = [codec.data_frame(0, n, payload(n)) for n in range(4)]
    for f in frames:
        rx.receive_data(f, 0.0)
    rx.receive_data(frames[2], 0.0)
    other = codec.data_frame(0, 2, payload(99))
    rx.receive_data(other, 0.0)
    evs = []
    while (e := rx.next_event()) is not None:
        evs.append(e)
    assert [e.num for e in of(evs, DuplicateReceived)] == [2]
    assert [(e.num, e.cause) for e in of(evs, Resynchronised)] == [(2, "peer_reset")]
    assert [e.data[:5] for e in of(evs, DataReceived)] == [payload(n) for n in (0, 1, 2, 3, 99)]
    assert rx.expected_num == 3 and rx.counters.resynchronisations == 1


@pytest.mark.parametrize("start", [0, 1, 500, *range(4088, 4096)])
def test_passive_receiver_starts_at_the_first_data_frame(start: int) -> None:
    """L9: a passive receiver takes the first DATA frame's NUM as E: nothing is lost."""
    rx = LinkConnection(LinkConfig(role="host", passive=True))
    for k in range(20):
        n = (start + k) % 4096
        rx.receive_data(codec.data_frame(0, n, payload(k)), 0.0)
    evs = []
    while (e := rx.next_event()) is not None:
        evs.append(e)
    assert [e.data[:5] for e in of(evs, DataReceived)] == [payload(k) for k in range(20)]
    assert rx.counters.sequenceErrorCounter == 0 and rx.counters.duplicateFrames == 0


@pytest.mark.parametrize("length", [127, 129])
def test_wrong_length_transfer_is_dropped_without_nak(link_pair: Pair, length: int) -> None:
    host, eyeq = link_pair.sides["host"], link_pair.sides["eyeq"]
    link_pair.mangle["host"] = lambda i, t: [(t + b"\0")[:length]] if i == 0 else [t]
    host.send(payload(0), tag=0, now=0.0)
    host.send(payload(1), tag=1, now=0.0)
    link_pair.run(0.1)
    assert eyeq.counters.formatErrorCounter == 1 and eyeq.counters.badLengthTransfers == 1
    assert nak_frames(link_pair, "eyeq") == []
    ev = link_pair.events("eyeq")
    assert [(e.nak_reason, e.num) for e in of(ev, FrameRejected)] == [(None, None)]
    assert [e.num for e in of(ev, DataReceived)] == [1]
    assert [(f.tag, f.reason) for f in of(link_pair.events("host"), SendFailed)] == [
        (0, "ack_timeout")
    ]


def test_peer_reset_resynchronises_after_three_naks(link_pair: Pair) -> None:
    host, eyeq = link_pair.sides["host"], link_pair.sides["eyeq"]
    for i in range(50):
        host.send(payload(i), tag=i, now=0.0)
    link_pair.run(1.0)
    link_pair.events("host"), link_pair.events("eyeq")
    assert eyeq.expected_num == 50
    host.reset()  # NUM jumps back to 0
    for i in range(5):
        host.send(payload(100 + i), tag=100 + i, now=link_pair.now)
    link_pair.run(2.0)
    assert eyeq.counters.sequenceErrorCounter == 3
    assert nak_frames(link_pair, "eyeq") == [(n, NakReason.OUT_OF_WINDOW) for n in (0, 1, 2)]
    ev = link_pair.events("eyeq")
    assert [e.num for e in of(ev, Resynchronised)] == [3]
    assert [e.num for e in of(ev, DataReceived)] == [3, 4]
    failed = of(link_pair.events("host"), SendFailed)
    assert [(f.tag, f.nak_reason) for f in failed] == [
        (100 + i, NakReason.OUT_OF_WINDOW) for i in range(3)
    ]


def test_missing_ack_fails_the_frame_at_exactly_ack_timeout() -> None:
    host = LinkConnection(LinkConfig(role="host"))
    host.send(payload(0), tag=7, now=0.0)
    assert len(host.data_to_send(0.0)) == 1
    assert host.get_timer() == pytest.approx(0.010)
    host.handle_timer(0.0099)
    assert host.next_event() is None and host.counters.busyFrames == 1
    now = host.get_timer()
    assert now is not None
    host.handle_timer(now)
    ev = host.next_event()
    assert isinstance(ev, SendFailed) and (ev.tag, ev.num, ev.reason) == (7, 0, "ack_timeout")
    assert host.counters.sendFailedErrorCounter == 1 and host.counters.busyFrames == 0
    # a late ACK is counted, never resent or raised
    host.receive_data(codec.ack(0), now + 0.001)
    assert isinstance(host.next_event(), UnexpectedAck)


def test_at_most_w_frames_in_flight_and_fifo_wait_is_counted() -> None:
    host = LinkConnection(LinkConfig(role="host", frame_gap=0.0))
    for i in range(20):
        host.send(payload(i), tag=i, now=0.0)
    out = host.data_to_send(0.0)
    assert len(out) == 8 and host.counters.busyFrames == 8
    assert host.counters.fifoNonEmptyCounter == 1
    assert host.data_to_send(0.001) == []
    host.receive_data(codec.ack(0), 0.002)
    assert len(host.data_to_send(0.002)) == 1


def test_queued_frames_fail_after_transmit_timeout() -> None:
    host = LinkConnection(LinkConfig(role="host", frame_gap=0.0))
    for i in range(10):
        host.send(payload(i), tag=i, now=0.0)
    host.data_to_send(0.0)  # 8 go out, 2 wait for the window
    host.handle_timer(0.010)  # the 8 time out (no ACKs)
    host.handle_timer(0.0249)
    lost = [e for e in iter(host.next_event, None) if isinstance(e, SendFailed)]
    assert [e.reason for e in lost] == ["ack_timeout"] * 8
    # the window is free again, but pretend the link is stuck: nothing is pulled before 25 ms
    host.handle_timer(0.025)
    lost = [e for e in iter(host.next_event, None) if isinstance(e, SendFailed)]
    assert [(e.tag, e.reason) for e in lost] == [(8, "transmit_timeout"), (9, "transmit_timeout")]
    assert host.counters.sendFailedErrorCounter == 10


def test_a_lost_frame_fails_its_tag_once_and_drops_its_queued_frames() -> None:
    host = LinkConnection(LinkConfig(role="host", frame_gap=0.0, window=2))
    for _ in range(5):
        host.send(payload(0), tag=42, now=0.0)
    host.data_to_send(0.0)
    host.receive_data(codec.nak(0, NakReason.CRC_MISMATCH), 0.001)
    assert host.queued == 0
    ev = [e for e in iter(host.next_event, None)]
    assert [(e.tag, e.reason) for e in ev if isinstance(e, SendFailed)] == [(42, "nak")]
    assert host.counters.sendFailedErrorCounter == 1
    host.receive_data(codec.ack(1), 0.002)  # the other in-flight frame settles silently
    assert [e for e in iter(host.next_event, None)] == []


@pytest.mark.parametrize(("role", "gap"), [("host", 0.0005), ("eyeq", 0.0002)])
def test_frames_respect_the_inter_frame_gap(role: str, gap: float) -> None:
    conn = LinkConnection(LinkConfig(role=role))  # type: ignore[arg-type]
    for i in range(3):
        conn.send(payload(i), tag=i, now=0.0)
    times = []
    now = 0.0
    while len(times) < 3:
        if conn.data_to_send(now):
            times.append(now)
        t = conn.get_timer()
        assert t is not None
        now = t
    assert times == pytest.approx([0.0, gap, 2 * gap])


@given(start=st.integers(4080, 4095), count=st.integers(1, 40))
def test_num_wraps_from_4095_to_0(start: int, count: int) -> None:
    pair = Pair(LinkConnection(LinkConfig(role="host")), LinkConnection(LinkConfig(role="eyeq")))
    pair.sides["host"].reset(tx_num=start)
    pair.sides["eyeq"].reset(expected=start)
    for i in range(count):
        pair.sides["host"].send(payload(i), tag=i, now=0.0)
    pair.run(5.0)
    nums = [e.num for e in pair.events("eyeq") if isinstance(e, DataReceived)]
    assert nums == [(start + i) % 4096 for i in range(count)]
    assert len([e for e in pair.events("host") if isinstance(e, Sent)]) == count
    assert pair.sides["eyeq"].counters.sequenceErrorCounter == 0


def test_data_frame_rsp_carries_last_accepted_num(link_pair: Pair) -> None:
    host, eyeq = link_pair.sides["host"], link_pair.sides["eyeq"]
    for i in range(3):
        eyeq.send(payload(i), tag=i, now=0.0)
    link_pair.run(0.1)
    host.send(payload(9), tag=9, now=link_pair.now)
    link_pair.run(0.2)
    data = [codec.decode(t) for _, who, t in link_pair.log if who == "host"]
    data = [f for f in data if f.kind is FrameKind.DATA]
    assert [(f.num, f.rsp) for f in data] == [(0, 2)]


def test_config_rejects_nonsense() -> None:
    from eyeq_spi.errors import LocalProtocolError
    with pytest.raises(LocalProtocolError):
        LinkConfig(role="gateway")  # type: ignore[arg-type]
    with pytest.raises(LocalProtocolError):
        LinkConfig(window=0)
    with pytest.raises(LocalProtocolError):
        LinkConfig(ack_timeout=-1)
