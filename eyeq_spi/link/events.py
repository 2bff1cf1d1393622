"""Events the link layer reports (docs/STYLE.md §4)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from eyeq_spi.link.frame import NakReason

SendFailReason = Literal["ack_timeout", "nak", "transmit_timeout", "reset"]
ResyncCause = Literal["nak_limit", "peer_reset", "peer_restart"]


@dataclass(frozen=True, slots=True)
class DataReceived:
    """An accepted DATA frame (L6): its NUM and its 122-byte data field."""

    num: int
    data: bytes


@dataclass(frozen=True, slots=True)
class Sent:
    """Every frame handed to :meth:`LinkConnection.send` under ``tag`` was ACKed."""

    tag: int


@dataclass(frozen=True, slots=True)
class SendFailed:
    """A frame under ``tag`` was lost (L7); the rest of the tag's queued frames were dropped."""

    tag: int
    num: int | None
    reason: SendFailReason
    nak_reason: NakReason | None = None


@dataclass(frozen=True, slots=True)
class FrameRejected:
    """A received transfer was rejected. ``nak_reason`` is None when no NAK was sent (L8, or a
    broken ACK/NAK, which is never answered)."""

    nak_reason: NakReason | None
    num: int | None
    detail: str


@dataclass(frozen=True, slots=True)
class DuplicateReceived:
    """A DATA frame with NUM in [E-W, E): ACKed again, payload dropped (L6)."""

    num: int


@dataclass(frozen=True, slots=True)
class Resynchronised:
    """The receiver took ``num`` as the new E: after out-of-window NAKs (L6, ``nak_limit``), an
    accepted NUM with other bytes (L6a, ``peer_reset``) or the reset peer's first frame (L10,
    ``peer_restart``). Nothing received before it may join what follows."""

    num: int
    cause: ResyncCause = "nak_limit"


@dataclass(frozen=True, slots=True)
class FramesSkipped:
    """An accepted NUM jumped over ``count`` frames; they are lost, nothing is resent (L6)."""

    expected: int
    num: int
    count: int


@dataclass(frozen=True, slots=True)
class UnexpectedAck:
    """An ACK or NAK for a NUM that is not in flight (late, duplicated or bogus)."""

    kind: str
    rsp: int


LinkEvent = (
    DataReceived | Sent | SendFailed | FrameRejected | DuplicateReceived | Resynchronised
    | FramesSkipped | UnexpectedAck
)
