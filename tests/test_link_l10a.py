"""Decision L10a: for 8 windows (64 frames) after its own reset, a receiver takes a DATA frame
with NUM 0 outside its window as the peer's restart, whatever its RSP: E goes to 0 at once, no
NAK, counted as a resynchronisation. After those 64 frames the L6 window rules apply again.
Virtual time: every call takes its ``now``."""

from __future__ import annotations

import pytest

from eyeq_spi.link.connection import RESTART_HORIZON, LinkConfig, LinkConnection
from eyeq_spi.link.events import DataReceived, DuplicateReceived, FrameRejected, Resynchronised
from eyeq_spi.link.frame import FrameCodec, NakReason

FC = FrameCodec()
W = LinkConfig().window
HORIZON = RESTART_HORIZON * W  # 64 frames


def _events(link: LinkConnection) -> list[object]:
    out: list[object] = []
    while (ev := link.next_event()) is not None:
        out.append(ev)
    return out


def _after_own_reset(first_num: int, frames: int) -> LinkConnection:
    """A receiver just reset (learning E, L10) that took ``frames`` DATA frames of the peer's
    old numbering, from ``first_num`` on."""
    rx = LinkConnection(LinkConfig(role="eyeq"))
    rx.reset(learn=True)
    for k in range(frames):
        rx.receive_data(FC.data_frame(7, (first_num + k) % 4096, bytes([k % 256])), 0.01 * k)
    rx.data_to_send(1.0)
    _events(rx)
    return rx


# E far from 0; E = 6, so NUM 0 lies in [E-W, E) and was never accepted (L6a would NAK it late)
@pytest.mark.parametrize(("first_num", "frames"), [(100, 20), (1, 5)])
def test_num_0_with_any_rsp_is_the_peer_restart_within_64_frames(first_num: int,
                                                                 frames: int) -> None:
    rx = _after_own_reset(first_num, frames)
    before = rx.counters.resynchronisations
    rx.receive_data(FC.data_frame(1234, 0, b"restart"), 1.0)  # NUM 0, RSP not 0
    events = _events(rx)
    assert [type(e) for e in events] == [Resynchronised, DataReceived]
    assert events[0].num == 0  # type: ignore[attr-defined]
    assert rx.counters.resynchronisations == before + 1
    assert rx.counters.naksSent == {}
    assert rx.expected_num == 1  # E went to 0 and the frame was accepted
    assert rx.data_to_send(2.0) == [FC.ack(0)]
    rx.receive_data(FC.data_frame(0, 1, b"next"), 2.0)  # the peer's numbering goes on
    assert [type(e) for e in _events(rx)] == [DataReceived]


def test_after_64_frames_num_0_outside_the_window_is_naked_again() -> None:
    rx = _after_own_reset(100, HORIZON)
    rx.receive_data(FC.data_frame(1234, 0, b"late restart"), 1.0)
    assert [type(e) for e in _events(rx)] == [FrameRejected]
    assert rx.counters.naksSent == {int(NakReason.OUT_OF_WINDOW): 1}


def test_the_last_frame_of_the_span_still_restarts() -> None:
    rx = _after_own_reset(100, HORIZON - 1)
    rx.receive_data(FC.data_frame(99, 0, b"restart"), 1.0)
    assert [type(e) for e in _events(rx)] == [Resynchronised, DataReceived]


def test_a_true_duplicate_of_the_restart_frame_stays_a_duplicate() -> None:
    """L6a still holds inside the span: the same NUM 0 frame, byte for byte, right after it
    was accepted, is ACKed again and dropped, not taken for a second restart."""
    rx = _after_own_reset(100, 10)
    frame = FC.data_frame(55, 0, b"restart")
    rx.receive_data(frame, 1.0)
    rx.receive_data(FC.data_frame(55, 1, b"next"), 1.1)
    _events(rx)
    rx.receive_data(frame, 1.2)
    assert [type(e) for e in _events(rx)] == [DuplicateReceived]


def test_without_a_reset_num_0_outside_the_window_is_naked() -> None:
    """A receiver that never reset has no span: L6 (NAK 0x001) as ever."""
    rx = LinkConnection(LinkConfig(role="eyeq"))
    for k in range(20):
        rx.receive_data(FC.data_frame(0, k, bytes([k])), 0.01 * k)
    _events(rx)
    rx.receive_data(FC.data_frame(7, 0, b"restart"), 1.0)
    assert [type(e) for e in _events(rx)] == [FrameRejected]
