"""Findings of the long fuzz run (``tools/fuzz.py``), replayed. A finding stays xfail(strict) until
it is fixed (or the decision behind it changes); then its xfail comes off and it stays here as a
regression test. The splice findings are closed by decision T6a (docs/PROTOCOL_DECISIONS.md)."""

from __future__ import annotations

from eyeq_spi.link.connection import LinkConfig
from eyeq_spi.transport.connection import TransportConnection
from eyeq_spi.transport.events import MessageReceived, TransferAborted
from tests.fuzz.app_targets import init_codec
from tests.fuzz.link_targets import transport_pair

SPLICE = bytes.fromhex(
    "05f9f9f9f9f9f9f92cf1f9f9f93af9f9f9ff00f45cfbf9f9f93af9f9f9ff00f45cfbd4ffffffffdffffff1f9f9"
    "f93af9f9f9ff00f45cfbf9f9f93af9f9f9ff00f45cfbd4ffffffffffffe86d92")
HALF_ROUNDS_OUT = bytes.fromhex("00308300000000000000b304")


def _frames(conn: TransportConnection) -> list[bytes]:
    return conn.data_to_send(1.0)


def test_t6a_limit_a_channel_that_reorders_across_a_reset_can_splice() -> None:
    """Fuzz finding (transport_pair, as first written): a first frame delayed across a second
    fast peer reset is taken by L6a for the reset itself, and the post-reset transfer with the
    same ID and NUMs is spliced onto it. No wire does this: SPI and byte streams keep order, and
    the fuzz target no longer holds a frame across a reset. Under such a channel no receiver rule
    can tell which frames continue the resynchronising first frame (T6a); this test pins the
    limit so that a change of behaviour is noticed."""
    tx, rx = TransportConnection(LinkConfig(role="eyeq")), TransportConnection(LinkConfig())
    a, b = b"A" * 394, b"B" * 394  # 4 frames each: first + 3 consecutive (T3, T4)
    tx.send(a, 0.0)
    delayed = _frames(tx)[0]  # A's first frame, NUM 0, ID 0: held on the wire
    tx.reset()  # the peer resets again before it arrives
    tx.send(b, 0.0)
    b_frames = []
    for _ in range(8):
        b_frames += tx.data_to_send(1.0 + len(b_frames))
    assert len(b_frames) == 4
    delivered = []
    for t in [b_frames[0], delayed, *b_frames[1:]]:  # B's first frame overtakes A's
        rx.receive_data(t, 2.0)
        while (ev := rx.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                delivered.append(ev.data)
    assert delivered == [a[:116] + b[116:]]


def test_a_reset_whose_first_frame_is_lost_is_never_spliced() -> None:
    """Fuzz finding (transport_pair_wire), fixed by T6a: after a peer reset whose first frame
    is lost, the next frame continues NUM and transfer ID seamlessly, so L6a sees no reset, and
    the open transfer used to be completed with the new message's bytes. The frame arrives after
    the open transfer's 25 ms deadline, and its padding is not zero: either rule stops it."""
    tx, rx = TransportConnection(LinkConfig(role="eyeq")), TransportConnection(LinkConfig())
    a, b = b"A" * 167, b"B" * 368  # A: first + 1 consecutive; B: first + 3 consecutive
    tx.send(a, 0.0)
    rx.receive_data(_frames(tx)[0], 1.0)  # A's first frame (NUM 0, ID 0) arrives...
    tx.reset()  # ...and the peer resets before A's consecutive frame is sent
    tx.send(b, 1.0)
    b_frames: list[bytes] = []
    for i in range(8):
        b_frames += tx.data_to_send(2.0 + i)
    delivered = []
    for t in b_frames[1:]:  # B's first frame (NUM 0) is lost: CRC error, truncation...
        rx.receive_data(t, 3.0)
        while (ev := rx.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                delivered.append(ev.data)
    assert all(m in (a, b) for m in delivered), [(m.count(b"A"), m.count(b"B"))
                                                  for m in delivered]


def test_init_codec_never_encodes_a_value_its_own_check_rejects() -> None:
    """Fuzz finding (init_codec), fixed: InitProtocolVersion = 0.5 lies inside the tolerance of
    half a step below the minimum 1, and used to round to raw 0, outside [1, 1]. A value inside
    the tolerance now snaps to the nearest raw value inside the range."""
    init_codec(HALF_ROUNDS_OUT)


def test_replay_transport_pair_artifact() -> None:
    """The fuzzer's own artifact of the delayed-frame splice, replayed through its oracle: the
    held frame now arrives before the reset, as on a wire, and nothing is spliced."""
    transport_pair(SPLICE)


def _lost_first_frame_after_reset(b_len: int, gap: float) -> tuple[list[bytes], list[str]]:
    """A's first frame arrives, the peer resets ``gap`` seconds later, and B's first frame is
    lost; returns what was delivered and the abort reasons."""
    tx, rx = TransportConnection(LinkConfig(role="eyeq")), TransportConnection(LinkConfig())
    a = b"A" * 167  # first (116 bytes) + one consecutive frame of 51
    tx.send(a, 0.0)
    rx.receive_data(_frames(tx)[0], 1.0)
    tx.reset()
    tx.send(b"B" * b_len, 1.0 + gap)
    b_frames: list[bytes] = []
    for i in range(8):
        b_frames += tx.data_to_send(1.0 + gap + i * 1e-3)
    delivered, aborts = [], []
    for t in b_frames[1:]:
        rx.receive_data(t, 1.0 + gap)
        while (ev := rx.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                delivered.append(ev.data)
            elif isinstance(ev, TransferAborted):
                aborts.append(ev.reason)
    return delivered, aborts


def test_t6a_the_last_consecutive_frame_must_have_zero_padding() -> None:
    """Within the 25 ms, B's consecutive frame would complete A, but it carries B's bytes where
    A's frame would end in zeros: it is NAKed 0x011 and A is aborted."""
    delivered, aborts = _lost_first_frame_after_reset(368, 0.001)
    assert delivered == []
    assert aborts[0] == "bad_padding"


def test_t6a_silence_is_judged_when_the_next_frame_arrives() -> None:
    """B has A's length, so its consecutive frame fits A's exactly; but no reset is faster than
    the 25 ms reassembly timeout, and the frame finds A timed out even though no timer ran."""
    delivered, aborts = _lost_first_frame_after_reset(167, 0.030)
    assert delivered == []
    assert aborts[0] == "timeout"


def test_t6a_limit_a_reset_faster_than_the_timeout_with_the_same_length_is_undetectable() -> None:
    """The documented limit of T6a: a reset within 25 ms, whose first frame is lost, followed by
    a message of the same length whose last frame is zero where the old one's padding is. No
    receiver can tell it from the real continuation; the application's E2E CRC must. This test
    pins the limit so that a change of behaviour is noticed."""
    tx, rx = TransportConnection(LinkConfig(role="eyeq")), TransportConnection(LinkConfig())
    tx.send(b"A" * 167, 0.0)
    rx.receive_data(_frames(tx)[0], 1.0)
    tx.reset()
    tx.send(b"B" * 116 + bytes(51), 1.001)
    b_frames = tx.data_to_send(1.001) + tx.data_to_send(1.002)
    rx.receive_data(b_frames[1], 1.002)
    got = [ev.data for ev in iter(rx.next_event, None) if isinstance(ev, MessageReceived)]
    assert got == [b"A" * 116 + bytes(51)]
