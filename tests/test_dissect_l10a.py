"""L10a in the dissector: a host that learns of an EyeQ reset late numbers its frames from 0
again with a stale RSP. The EyeQ's own receiver takes that NUM 0 as the host's restart (it was
reset itself, within 64 frames), so the dissector's passive receiver of the host's channel,
which uses the same link receiver, must take it too: no rejected frame, every message decoded,
on the reference and on the fast path."""

from __future__ import annotations

from typing import Any

import pytest

from eyeq_spi.capture.pcapng_fast import chunks_from_transfers
from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect import engine
from eyeq_spi.dissect import engine_fast as fast
from eyeq_spi.link.frame import FrameCodec
from eyeq_spi.transport.segment import segment

pytestmark = pytest.mark.twin

FC = FrameCodec()
MC = MessageCodec()
REQ = "GetEyeQExtendedState"


def _capture(late_restart_rsp: int) -> list[Transfer]:
    """The host sends requests numbered 0..19, each answered; the EyeQ boots again (its first
    frame at NUM 0, RSP 0); the host, not yet aware, sends 3 more frames in its old numbering,
    then learns of the reset and numbers from 0 with RSP ``late_restart_rsp``. Every DATA
    frame is ACKed."""
    out: list[Transfer] = []
    t = 0.0
    nums = {"h2e": 0, "e2h": 0}

    def send(direction: str, msg: bytes, rsp: int) -> None:
        nonlocal t
        other = "e2h" if direction == "h2e" else "h2e"
        for part in segment(msg, 0):
            out.append(Transfer(round(t, 6), direction, FC.data_frame(rsp, nums[direction], part)))
            out.append(Transfer(round(t + 0.0001, 6), other, FC.ack(nums[direction])))
            nums[direction] = (nums[direction] + 1) % 4096
            t += 0.001

    for tag in range(20):
        send("h2e", MC.mesp.encode_request(REQ, tag, {}), nums["e2h"])
        send("e2h", MC.mesp.encode_reply(REQ, tag, 0, {"mainState": 2, "subState": 0}),
             nums["h2e"] - 1)
    nums["e2h"] = 0  # the EyeQ boots again: its first frame is NUM 0, RSP 0 (L4)
    send("e2h", MC.mesp.encode_reply(REQ, 19, 0, {"mainState": 2, "subState": 0}), 0)
    for tag in range(20, 23):  # the host has not noticed yet
        send("h2e", MC.mesp.encode_request(REQ, tag, {}), 0)
    nums["h2e"] = 0  # now it has (0x41 Main_State): L10, from 0, with a stale RSP (L10a)
    for tag in range(23, 30):
        send("h2e", MC.mesp.encode_request(REQ, tag, {}), late_restart_rsp)
    return out


def _host_requests(recs: list[dict[str, Any]]) -> int:
    return sum(r.get("kind") == "message" and r.get("direction") == "h2e" for r in recs)


def _rejected(recs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in recs if r.get("type") == "frame_rejected"]


@pytest.mark.parametrize("rsp", [0, 5, 4095])
def test_a_late_restart_is_the_hosts_restart(rsp: int) -> None:
    recs = list(engine.iter_records(_capture(rsp)))
    assert not _rejected(recs), _rejected(recs)
    assert _host_requests(recs) == 30


@pytest.mark.parametrize("chunk", [5, 1 << 15])
def test_the_fast_path_agrees(chunk: int) -> None:
    records = _capture(5)
    assert list(fast.iter_records(chunks_from_transfers(records, chunk))) == \
        list(engine.iter_records(records))
