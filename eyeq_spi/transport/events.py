"""Events the transport layer reports (decisions T5, T6)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

AbortReason = Literal["num_gap", "wrong_id", "no_open_transfer", "timeout", "new_first_frame",
                      "interleaved", "reset", "resynchronised", "bad_padding"]


@dataclass(frozen=True, slots=True)
class MessageReceived:
    data: bytes
    frames: tuple[int, ...]  # the NUMs of the frames that carried it
    transfer_id: int | None  # None for a single frame


@dataclass(frozen=True, slots=True)
class MessageSent:
    message_id: int


@dataclass(frozen=True, slots=True)
class MessageSendFailed:
    message_id: int
    reason: str  # the link's SendFailed reason


@dataclass(frozen=True, slots=True)
class TransferAborted:
    """A multi-frame reception was abandoned (T6). Counted, never raised."""

    reason: AbortReason
    transfer_id: int | None
    received: int  # message bytes received before the abort
    total: int | None


@dataclass(frozen=True, slots=True)
class TransferIncomplete:
    """A passive receiver (L9) saw only part of a transfer because the capture began or ended
    inside it: ``where`` is ``"start"`` (consecutive frames before any first frame) or
    ``"end"`` (still open when the input ended). Not a protocol error."""

    where: Literal["start", "end"]
    transfer_id: int | None
    received: int  # message bytes seen
    total: int | None


TransportEvent = (
    MessageReceived | MessageSent | MessageSendFailed | TransferAborted | TransferIncomplete
)
