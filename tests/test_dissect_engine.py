"""Decisions L9 (passive receivers) and L6a (duplicate, reset or late frame) end to end: the
transport never joins frames from both sides of a peer reset, and the dissector reads captures
that begin or end anywhere in the NUM space or inside a transfer."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from eyeq_spi.capture.pcapng_io import CaptureWriter, Transfer
from eyeq_spi.cli import main
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect.engine import iter_records
from eyeq_spi.link import LinkConfig
from eyeq_spi.link.events import Resynchronised
from eyeq_spi.link.frame import FrameCodec
from eyeq_spi.transport import MessageReceived, TransferAborted, TransportConnection
from eyeq_spi.transport.segment import segment

FC = FrameCodec()


def drain(conn: TransportConnection) -> list[Any]:
    out = []
    while (e := conn.next_event()) is not None:
        out.append(e)
    return out


def test_no_splice_across_a_fast_peer_reset_at_the_num_wrap() -> None:
    """Fault-campaign defect 1: the receiver starts at NUM 4094; the peer sends part of a
    6-frame message across the wrap, resets, and sends another 6-frame message with the same
    transfer ID. The new first frame (NUM 0) repeats an accepted NUM with other bytes: L6a says
    the peer reset. Before the fix it was taken as a duplicate and NUM 1 was appended to the old
    transfer, delivering a spliced message."""
    tx = TransportConnection(LinkConfig(role="eyeq"))
    rx = TransportConnection(LinkConfig(role="host"))
    tx.reset(tx_num=4094)
    rx.reset(expected=4094)
    old, new = bytes([0xAA]) * 600, bytes([0x55]) * 600
    tx.send(old, 0.0)
    wire = tx.data_to_send(0.0)
    for i in range(1, 20):
        wire += tx.data_to_send(i * 0.001)
    assert len(wire) == 6
    for t in wire[:3]:  # 4094, 4095, 0 arrive; then the peer resets
        rx.receive_data(t, 0.01)
    tx.reset()
    tx.send(new, 0.02)
    wire2: list[bytes] = []
    for i in range(20):
        wire2 += tx.data_to_send(0.02 + i * 0.001)
    for t in wire2:
        rx.receive_data(t, 0.03)
    ev = drain(rx)
    got = [e.data for e in ev if isinstance(e, MessageReceived)]
    assert got == [new]
    assert [e.cause for e in ev if isinstance(e, Resynchronised)] == ["peer_reset"]
    assert [e.reason for e in ev if isinstance(e, TransferAborted)] == ["resynchronised"]


def capture(start: int, messages: list[bytes], *, skip_head: int = 0,
            cut_tail: int = 0) -> list[Transfer]:
    """e2h DATA frames numbered from ``start``, dropping ``skip_head`` frames at the start and
    ``cut_tail`` at the end (a capture that begins or ends inside a transfer)."""
    frames: list[bytes] = []
    tid = 0
    for m in messages:
        parts = segment(m, tid)
        if len(parts) > 1:
            tid = (tid + 1) % 256
        frames += parts
    recs = [Transfer(i * 0.0002, "e2h", FC.data_frame(0, (start + i) % 4096, p))
            for i, p in enumerate(frames)]
    return recs[skip_head:len(recs) - cut_tail]


VERSIONS = MessageCodec().mesp.encode_request("GetEyeQVersions", 5, {})
MESSAGES = [b"\x41" + bytes(116), bytes([0x10]) * 30, bytes(range(256)) * 2, b"\x41" + bytes(60)]


def events(records: list[dict[str, Any]]) -> list[str]:
    return [r["type"] for r in records if r["kind"] == "event"]


@pytest.mark.parametrize("start", [0, 1, 500, *range(4088, 4096)])
def test_capture_starting_anywhere_loses_nothing(start: int) -> None:
    out = list(iter_records(capture(start, MESSAGES * 3)))
    assert [r["length"] for r in out if r["kind"] == "message"] == [len(m) for m in MESSAGES * 3]
    assert events(out) == []


@pytest.mark.parametrize("start", [0, 500, 4093])
def test_capture_starting_and_ending_inside_a_transfer(start: int) -> None:
    msgs = [bytes(range(256)) * 2, b"\x41" + bytes(60), bytes(range(200)) * 2]
    out = list(iter_records(capture(start, msgs, skip_head=2, cut_tail=1)))
    assert [r["length"] for r in out if r["kind"] == "message"] == [61]
    assert events(out) == ["incomplete_at_start", "incomplete_at_end"]
    end = [r for r in out if r["kind"] == "event"][-1]
    assert (end["transfer_id"], end["received"], end["total"]) == (1, 356, 400)


def test_incomplete_transfers_alone_exit_0(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "mid.pcapng"
    with CaptureWriter(path) as w:
        for r in capture(700, [bytes(range(256)) * 2, VERSIONS] * 2,
                         skip_head=3, cut_tail=2):
            w.write("e2h", r.time or 0.0, r.data)
    assert main(["dissect", str(path), "--stats"]) == 0
    out = capsys.readouterr().out
    assert "incomplete transfers: at start 1, at end 1" in out
