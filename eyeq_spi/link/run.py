"""The rest of a message a sender's link is in the middle of, as
:meth:`~eyeq_spi.link.connection.LinkConnection.data_run` tells it to the runner's express
handover (runner/virtual_fast.py), which hands that rest over in one step."""

from __future__ import annotations

from dataclasses import dataclass

from eyeq_spi.link.frame import FrameCodec


@dataclass(slots=True)
class DataRun:
    """The rest of the message a sender's link is sending (:meth:`LinkConnection.data_run`):
    its frames in flight (released at ``sent``), then its frames still queued, which go out
    from ``next_tx`` on, ``gap`` apart (frameFlowControl), as long as nothing else is due before
    ``until`` and fewer than ``window`` frames are in flight. ``acks[k]``: the ACK this link
    takes as frame k's. Read by the runner's express handover (runner/virtual_fast.py)."""

    nums: list[int]
    sent: list[float]
    datas: list[bytes]  # the data fields of the queued frames
    acks: list[bytes]
    next_tx: float
    gap: float
    ack_timeout: float
    window: int
    until: float  # the first queued frame's transmit deadline, or an earlier deadline
    more: bool  # frames of another message are queued behind this one
    rsp: int
    codec: FrameCodec

    def frame(self, k: int) -> bytes:
        """Queued frame ``k`` as :meth:`LinkConnection.data_to_send` will release it."""
        return self.codec.data_frame(self.rsp, self.nums[k], self.datas[k - len(self.sent)])
