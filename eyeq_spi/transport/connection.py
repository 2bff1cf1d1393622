"""Sans-IO transport connection: segmentation and reassembly over one link connection.

``send`` queues all frames of a message on the link under one tag, back to back (T5); the link
asks :meth:`_check_header` about every in-window DATA frame before it ACKs it (NAK 0x011, T6).
A ``Resynchronised`` link event aborts the open transfer before the frame that caused it is
reassembled (T6a). The rules and counters are in docs/architecture.md ("Transport"),
docs/specs.md and docs/PROTOCOL_DECISIONS.md (T1-T6a); other link events pass through, so one
``next_event()`` loop sees everything.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field

from eyeq_spi.catalog.link import link_spec
from eyeq_spi.link.connection import LinkConfig, LinkConnection
from eyeq_spi.link.events import DataReceived, LinkEvent, Resynchronised, SendFailed, Sent
from eyeq_spi.link.frame import SEQ_MODULO, NakReason
from eyeq_spi.transport import segment as seg
from eyeq_spi.transport.events import (
    AbortReason,
    MessageReceived,
    MessageSendFailed,
    MessageSent,
    TransferAborted,
    TransferIncomplete,
    TransportEvent,
)

_T = link_spec()["transport"]

Event = TransportEvent | LinkEvent


@dataclass
class TransportConfig:
    receive_limit: int | None = None  # None: the role's limit (8191 host, 512 EyeQ)
    reassembly_timeout: float = _T["reassembly_timeout"]


@dataclass
class _Open:
    transfer_id: int
    total: int
    buf: bytearray
    deadline: float
    nums: list[int]  # the NUMs of its frames so far


@dataclass
class TransportCounters:
    messagesSent: int = 0
    messagesReceived: int = 0
    messagesFailed: int = 0
    framesDiscarded: int = 0  # consecutive frames of a transfer that was already aborted
    incompleteTransfers: int = 0  # L9: cut by the start or end of a passive receiver's input
    transferAborts: Counter[str] = field(default_factory=Counter)


class TransportConnection:
    def __init__(
        self, link_config: LinkConfig | None = None, config: TransportConfig | None = None
    ) -> None:
        self.link = LinkConnection(link_config, payload_check=self._check_header)
        self.config = config or TransportConfig()
        if self.config.receive_limit is None:
            self.config.receive_limit = int(_T["receive_limit"][self.link.config.role])
        self.counters = TransportCounters()
        self._events: deque[Event] = deque()
        self._open: _Open | None = None
        self._dead_id: int | None = None  # the last aborted transfer: its stragglers are dropped
        self._seen_first = False  # L9: orphans before any first frame began before the capture
        self._next_message_id = 0
        self._next_transfer_id = 0

    def reset(self, *, tx_num: int = 0, expected: int = 0, transfer_id: int = 0,
              learn: bool = False, restart_span: int = 0) -> None:
        """Power-up state of both layers (the link's pending messages fail); the arguments are
        :meth:`LinkConnection.reset`'s, and the first transfer ID."""
        if not 0 <= transfer_id < seg.ID_MODULO:
            raise ValueError("transfer_id must be 0..255")
        self._abort("reset")
        self.link.reset(tx_num=tx_num, expected=expected, learn=learn,
                        restart_span=restart_span)
        self._next_transfer_id = transfer_id
        self._drain_link(0.0)

    def restart(self) -> None:
        """L10: both link directions start afresh (:meth:`LinkConnection.restart`) and a
        transfer still open is aborted (L6a)."""
        self._abort("reset")
        self._dead_id = None
        self.link.restart()

    # -- send -------------------------------------------------------------------------------
    def send(self, message: bytes, now: float) -> int:
        """Queue ``message``; returns the id that ``MessageSent``/``MessageSendFailed`` carry."""
        tid = self._next_transfer_id
        payloads = seg.segment(message, tid)
        if len(payloads) > 1:
            self._next_transfer_id = (tid + 1) % seg.ID_MODULO
        mid = self._next_message_id
        self._next_message_id += 1
        for payload in payloads:
            self.link.send(payload, mid, now)
        return mid

    def data_to_send(self, now: float) -> list[bytes]:
        return self.link.data_to_send(now)

    # -- timers -----------------------------------------------------------------------------
    def get_timer(self) -> float | None:
        due = self.link.get_timer()
        if self._open is not None and (due is None or self._open.deadline < due):
            due = self._open.deadline
        return due

    def handle_timer(self, now: float) -> None:
        self.link.handle_timer(now)
        if self._open is not None and self._open.deadline <= now:
            self._abort("timeout")
        self._drain_link(now)

    # -- receive ----------------------------------------------------------------------------
    def receive_data(self, transfer: bytes, now: float) -> None:
        if self._open is not None and self._open.deadline <= now:
            self._abort("timeout")  # T6: the silence ended before this frame, timer or not
        self.link.receive_data(transfer, now)
        self._drain_link(now)

    def next_event(self) -> Event | None:
        return self._events.popleft() if self._events else None

    def _check_header(self, num: int, data: bytes) -> NakReason | None:
        ttype = data[0]
        limit = self.config.receive_limit or seg.MAX_TOTAL
        if ttype == seg.SINGLE:
            return None if 1 <= data[1] <= seg.SINGLE_MAX else NakReason.FORMAT_ERROR
        if ttype == seg.FIRST:
            total = int.from_bytes(data[2:6], "little")
            if total > limit and total >= seg.FIRST_TOTAL_MIN:
                self.link.counters.rcvOverflowErrors += 1
                return NakReason.FORMAT_ERROR
            return None if seg.FIRST_TOTAL_MIN <= total <= limit else NakReason.FORMAT_ERROR
        if ttype == seg.CONSECUTIVE:
            transfer = self._open
            if transfer is not None and data[1] != transfer.transfer_id:
                self._abort("wrong_id")
                return NakReason.FORMAT_ERROR
            if transfer is not None and num == (transfer.nums[-1] + 1) % SEQ_MODULO:
                remaining = transfer.total - len(transfer.buf)
                if remaining < seg.CONSECUTIVE_CHUNK and any(data[2 + remaining :]):
                    self._abort("bad_padding")  # T4: the rest is zero; this is another transfer
                    return NakReason.FORMAT_ERROR
            return None
        return NakReason.FORMAT_ERROR

    def _drain_link(self, now: float) -> None:
        while (ev := self.link.next_event()) is not None:
            if isinstance(ev, DataReceived):
                self._on_payload(ev.num, ev.data, now)
            elif isinstance(ev, Sent):
                self.counters.messagesSent += 1
                self._events.append(MessageSent(ev.tag))
            elif isinstance(ev, SendFailed):
                self.counters.messagesFailed += 1
                self._events.append(MessageSendFailed(ev.tag, ev.reason))
            elif isinstance(ev, Resynchronised):
                self._events.append(ev)
                self._abort("resynchronised")
                self._dead_id = None  # the peer started over: no straggler to expect
            else:
                self._events.append(ev)

    def _on_payload(self, num: int, data: bytes, now: float) -> None:
        ttype = data[0]
        if ttype == seg.SINGLE:
            if self._open is not None:
                self._abort("interleaved")
            self._deliver(data[2 : 2 + data[1]], (num,), None)
            return
        if ttype == seg.FIRST:
            if self._open is not None:
                self._abort("new_first_frame")
            self._dead_id = None
            self._seen_first = True
            total = int.from_bytes(data[2:6], "little")
            self._open = _Open(
                data[1], total, bytearray(data[6 : 6 + seg.FIRST_CHUNK]),
                now + self.config.reassembly_timeout, [num],
            )
            return
        # consecutive (the header check let only these through)
        transfer = self._open
        if transfer is None:
            if data[1] == self._dead_id:
                self.counters.framesDiscarded += 1
                return
            if self.link.config.passive and not self._seen_first:
                self._dead_id = data[1]  # L9: the rest of this transfer is quietly dropped
                self.counters.incompleteTransfers += 1
                self._events.append(TransferIncomplete("start", data[1], 0, None))
                return
            self.counters.transferAborts["no_open_transfer"] += 1
            self._events.append(TransferAborted("no_open_transfer", data[1], 0, None))
            return
        if num != (transfer.nums[-1] + 1) % SEQ_MODULO:
            self._abort("num_gap")
            return
        take = min(seg.CONSECUTIVE_CHUNK, transfer.total - len(transfer.buf))
        transfer.buf += data[2 : 2 + take]
        transfer.nums.append(num)
        transfer.deadline = now + self.config.reassembly_timeout
        if len(transfer.buf) >= transfer.total:
            self._open = None
            self._deliver(bytes(transfer.buf), tuple(transfer.nums), transfer.transfer_id)

    def finish(self) -> None:
        """End of a passive receiver's input (L9): an open transfer is incomplete."""
        transfer = self._open
        if transfer is None:
            return
        self._open = None
        self.counters.incompleteTransfers += 1
        self._events.append(TransferIncomplete("end", transfer.transfer_id, len(transfer.buf),
                                               transfer.total))

    def _deliver(self, message: bytes, nums: tuple[int, ...], tid: int | None) -> None:
        self.counters.messagesReceived += 1
        self._events.append(MessageReceived(message, nums, tid))

    def _abort(self, reason: AbortReason) -> None:
        transfer = self._open
        if transfer is None:
            return
        self._open = None
        self._dead_id = transfer.transfer_id
        self.counters.transferAborts[reason] += 1
        self._events.append(TransferAborted(reason, transfer.transfer_id, len(transfer.buf),
                                            transfer.total))
