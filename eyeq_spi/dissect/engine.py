"""The dissector engine: transfers in, JSON-ready records out (the ``--json`` contract).

Each direction has a passive receiver (L9): a :class:`TransportConnection` in the role of the
side that received that channel, fed with its DATA frames, so duplicates, window errors, NUM
gaps and aborted transfers are judged as the real receiver judges them; its ACK/NAKs are
dropped. Frame records come out in capture order, a message record after the frame that
completed it; memory stays bounded.

:meth:`Dissector.feed` takes one transfer. A caller that has checked a clean run of frames
itself (:mod:`.engine_fast`) hands its whole messages over with :meth:`Dissector.accept_clean`
and its last transfers with :meth:`Dissector.resume`, which leaves the receiver where ``feed``
of the run would have.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, field
from typing import Any

from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.catalog.bringup import SWITCH_APP_NAME
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import DaspCounters, MessageCodec
from eyeq_spi.link.connection import LinkConfig
from eyeq_spi.link.events import (
    DuplicateReceived,
    FrameRejected,
    FramesSkipped,
    Resynchronised,
)
from eyeq_spi.link.frame import FRAME_SIZE, SEQ_MODULO, FrameCodec, FrameKind
from eyeq_spi.transport.connection import TransportConnection
from eyeq_spi.transport.events import MessageReceived, TransferAborted, TransferIncomplete
from eyeq_spi.transport.segment import FIRST

TRANSPORT_NAMES = {0x00: "single", 0x01: "first", 0x02: "consecutive"}
OTHER_DIRECTION: dict[str | None, str | None] = {"h2e": "e2h", "e2h": "h2e"}
RECEIVER = {"h2e": "eyeq", "e2h": "host", None: "host"}


KIND_NAMES = {int(k): k.name for k in FrameKind}
LINK_EVENT_TYPES: dict[type, str] = {DuplicateReceived: "duplicate",
                                     Resynchronised: "resynchronised",
                                     FramesSkipped: "frames_skipped"}


def frame_record(index: int, time: float | None, direction: str | None, length: int,
                 header: tuple[int, int, int, int] | None = None, crc_ok: bool = False,
                 transport: tuple[int, int] = (0, 0)) -> dict[str, Any]:
    """The ``--json`` record of one transfer (docs/dissector.md): ``length`` bytes; for a
    128-byte frame its ``header`` fields (D, R, RSP, NUM; L1), CRC verdict (L3) and
    ``transport`` bytes 6 and 7 (T1: the transport type, then a single frame's size or a
    transfer ID). The frame type is INVALID unless D is a known kind and R is 0 (L2)."""
    rec: dict[str, Any] = {
        "kind": "frame", "index": index, "time": time, "direction": direction,
        "frame_type": "INVALID", "num": None, "rsp": None, "crc_ok": False,
        "transport": None, "transfer_id": None, "nak_reason": None,
    }
    if length != FRAME_SIZE or header is None:
        rec["length"] = length
        return rec
    dfield, rfield, rsp, num = header
    rec["num"], rec["rsp"], rec["crc_ok"] = num, rsp, crc_ok
    if rfield == 0 and dfield in KIND_NAMES:
        rec["frame_type"] = KIND_NAMES[dfield]
    if dfield == FrameKind.NAK:
        rec["nak_reason"] = num
    elif dfield != FrameKind.ACK:  # DATA, or a D of no known kind
        name = TRANSPORT_NAMES.get(transport[0])
        rec["transport"] = name
        if name in ("first", "consecutive"):
            rec["transfer_id"] = transport[1]
    return rec


def jsonable(value: Any) -> Any:
    if isinstance(value, bytes | bytearray):
        return value.hex()
    if isinstance(value, dict):
        return {k: jsonable(x) for k, x in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(x) for x in value]
    return value


TransferFrames = list[tuple[bytes, "float | None", int, int]]
"""The frames of one transfer: (bytes, time, NUM, capture index) each."""


@dataclass
class _Direction:
    """One direction's passive receiver (transport connection), its NUM -> capture index map,
    E2E state and DASP counters."""

    conn: TransportConnection
    index_of_num: dict[int, int] = field(default_factory=dict)
    e2e: E2EState = field(default_factory=E2EState)
    dasp_counters: DaspCounters = field(default_factory=DaspCounters)
    # L10: the NUM of a Switch EyeQ Application request's last frame; its sender may number
    # its next frame from 0 (the reset it asked for starts its link afresh)
    restart_after: int | None = None
    clean_frames: int = 0  # DATA frames of clean runs since the receiver last took a frame


class Dissector:
    """``on_message(data)`` sees each reassembled message's bytes before it is decoded."""

    def __init__(self, sw: str | None = None, codec: MessageCodec | None = None, *,
                 on_message: Callable[[bytes], None] | None = None) -> None:
        self.codec = codec or MessageCodec(sw)
        self.on_message = on_message
        self.frames = FrameCodec()
        self._dirs: dict[str | None, _Direction] = {}
        self.index = 0
        self.last_time: float | None = None

    # -- the public API of a caller that checks clean runs of frames itself ----------------------
    def open_direction(self, direction: str | None) -> None:
        """Make the receiver of ``direction`` now (receivers are made in the order they are
        first seen, which the order of their end-of-capture records follows)."""
        self._dir(direction)

    def expected_num(self, direction: str | None) -> int:
        """The NUM the receiver of ``direction`` expects next."""
        return self._dir(direction).conn.link.expected_num

    def next_deadline(self) -> float | None:
        """The earliest timer of any receiver (an open transfer's reassembly deadline)."""
        timers = (receiver.conn.get_timer() for receiver in self._dirs.values())
        times = [at for at in timers if at is not None]
        return min(times) if times else None

    def message_state(self, direction: str | None) -> tuple[E2EState, DaspCounters]:
        """The E2E rolling counters (D5) and DASP counters (D1) the messages received on
        ``direction`` are judged against; a caller that judges many messages at once
        (:mod:`eyeq_spi.codec.message_fast`) reads and advances them."""
        receiver = self._dir(direction)
        return receiver.e2e, receiver.dasp_counters

    def accept_clean(self, direction: str | None, data: bytes, nums: tuple[int, ...],
                     transfer_id: int | None, frames: list[int | None],
                     time: float | None) -> dict[str, Any]:
        """The record of a whole message a clean run of frames delivered on ``direction``
        (128 bytes, CRC good, DATA, NUMs in order, transfer whole and in time), completed at
        ``time`` by the frames at capture indices ``frames``: what :meth:`feed` would give."""
        self.last_time = time
        rec = self._message(direction, self._dir(direction),
                            MessageReceived(data, nums, transfer_id))
        rec["frames"] = frames
        return rec

    def note_frames(self, direction: str | None, nums: Iterable[int],
                    indices: Iterable[int]) -> None:
        """DATA frames of a clean run on ``direction``, in order: their NUMs and capture
        indices (the message records of later frames name their frames by them)."""
        receiver = self._dir(direction)
        nums = list(nums)
        receiver.index_of_num.update(zip(nums, indices, strict=True))
        receiver.clean_frames += len(nums)  # the receiver did not see them: L10a's span runs on

    def resume(self, direction: str | None, last_first: TransferFrames | None,
               tail: list[TransferFrames], open_transfer: TransferFrames | None) -> None:
        """After a clean run on ``direction``: its receiver takes these frames again, output
        dropped, and stands as :meth:`feed` of the whole run would leave it. ``tail``: the
        run's last whole transfers (at least a window, L6a); ``last_first``: its last
        multi-frame transfer when ``tail`` has none (a straggler is judged by its transfer ID);
        ``open_transfer``: the transfer still open at its end."""
        receiver = self._dir(direction)
        units = tail + ([open_transfer] if open_transfer else [])
        replays = [units] if units else []
        if last_first is not None and not any(u[0][0][6] == FIRST for u in units):
            replays.insert(0, [last_first])
        # L10a: the restart span stands where feeding the whole run would have left it (the
        # run's frames count against it; the replayed ones are counted by the replay itself)
        left = max(0, receiver.conn.link.restart_span - receiver.clean_frames)
        receiver.clean_frames = 0
        for unit_list in replays:
            replayed = sum(len(unit) for unit in unit_list)
            _replay(receiver.conn, unit_list, left + replayed if left else 0)
        if open_transfer:
            receiver.index_of_num.update((f[2], f[3]) for f in open_transfer)

    def _dir(self, direction: str | None) -> _Direction:
        receiver = self._dirs.get(direction)
        if receiver is None:
            role = RECEIVER[direction]
            receiver = _Direction(TransportConnection(
                LinkConfig(role=role, passive=True)))  # type: ignore[arg-type]
            self._dirs[direction] = receiver
        return receiver

    def feed(self, transfer: Transfer) -> Iterator[dict[str, Any]]:
        idx = self.index
        self.index += 1
        time_s = transfer.time
        receiver = self._dir(transfer.direction)
        if time_s is not None:
            yield from self.run_timers(time_s)
            self.last_time = time_s
        data = transfer.data
        if len(data) == FRAME_SIZE:
            dfield, rfield, rsp, num, crc_ok = self.frames.check(data)
            frame_rec = frame_record(idx, time_s, transfer.direction, FRAME_SIZE,
                                     (dfield, rfield, rsp, num), crc_ok, (data[6], data[7]))
            if dfield == FrameKind.DATA:
                receiver.index_of_num[num] = idx
        else:
            frame_rec = frame_record(idx, time_s, transfer.direction, len(data))
        yield frame_rec
        if frame_rec["frame_type"] in ("ACK", "NAK"):
            return  # acknowledgements of the other channel's frames: nothing to reassemble
        after = receiver.restart_after
        if after is not None and frame_rec["frame_type"] == "DATA" and frame_rec["crc_ok"]:
            receiver.restart_after = None
            if frame_rec["num"] == 0 and after != SEQ_MODULO - 1:
                # L10: the host asked for a reset (Switch EyeQ Application) and numbers its
                # frames after it from 0: a receiver takes this one as its start
                receiver = self._reset_direction(transfer.direction)
                yield {"kind": "event", "type": "driver_reset", "direction": transfer.direction,
                       "index": idx}
        if (frame_rec["frame_type"] == "DATA" and frame_rec["num"] == 0 and frame_rec["rsp"] == 0
                and frame_rec["crc_ok"] and receiver.conn.link.expected_num != 0):
            # L4: NUM is 0 after a reset. The real receiver was reset with its peer (both SPI
            # drivers restart together), so the passive one must start over too, or it would
            # NAK frames the real one accepted.
            receiver = self._reset_direction(transfer.direction)
            yield {"kind": "event", "type": "driver_reset", "direction": transfer.direction,
                   "index": idx}
            # L10/L10a: the side that restarted starts its own receiver over too, so for its
            # first 64 frames it takes a NUM 0 of the other side as that side's (late) restart,
            # whatever its RSP, as the real receiver does
            other = self._dirs.get(OTHER_DIRECTION.get(transfer.direction))
            if other is not None:
                other.conn.link.restart()
        conn = receiver.conn
        conn.receive_data(data, time_s if time_s is not None else 0.0)
        conn.data_to_send(float("inf"))  # our passive receiver's ACK/NAKs go nowhere
        yield from self._events(transfer.direction, receiver)

    def _reset_direction(self, direction: str | None) -> _Direction:
        old = self._dirs.pop(direction)
        receiver = self._dir(direction)
        receiver.index_of_num = old.index_of_num
        return receiver

    def run_timers(self, now: float) -> Iterator[dict[str, Any]]:
        """The records of every receiver timer due at ``now`` (:meth:`feed` runs them before a
        transfer of that time)."""
        for direction, receiver in self._dirs.items():
            timer = receiver.conn.get_timer()
            while timer is not None and timer <= now:
                receiver.conn.handle_timer(timer)
                receiver.conn.data_to_send(float("inf"))
                yield from self._events(direction, receiver)
                nxt = receiver.conn.get_timer()
                if nxt == timer:
                    break
                timer = nxt

    def finish(self) -> Iterator[dict[str, Any]]:
        """End of capture: a transfer still open is incomplete, not timed out (L9)."""
        for direction, receiver in self._dirs.items():
            receiver.conn.finish()
            yield from self._events(direction, receiver)

    def _events(self, direction: str | None, receiver: _Direction) -> Iterator[dict[str, Any]]:
        while (ev := receiver.conn.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                if self.on_message is not None:
                    self.on_message(ev.data)
                yield self._message(direction, receiver, ev)
            elif isinstance(ev, TransferAborted):
                yield {"kind": "event", "type": "transfer_aborted", "direction": direction,
                       **asdict(ev), "index": self.index - 1}
            elif isinstance(ev, TransferIncomplete):
                yield {"kind": "event", "type": f"incomplete_at_{ev.where}",
                       "direction": direction, "transfer_id": ev.transfer_id,
                       "received": ev.received, "total": ev.total, "index": self.index - 1}
            elif isinstance(ev, FrameRejected):
                yield {"kind": "event", "type": "frame_rejected", "direction": direction,
                       "nak_reason": None if ev.nak_reason is None else int(ev.nak_reason),
                       "num": ev.num, "detail": ev.detail, "index": self.index - 1}
            elif isinstance(ev, DuplicateReceived | Resynchronised | FramesSkipped):
                yield {"kind": "event", "direction": direction, "index": self.index - 1,
                       "type": LINK_EVENT_TYPES[type(ev)], **asdict(ev)}

    def _message(self, direction: str | None, receiver: _Direction,
                 ev: MessageReceived) -> dict[str, Any]:
        out = self.codec.decode(ev.data, receiver.e2e if ev.data[:1] == b"\x65" else None)
        if out.name == SWITCH_APP_NAME and out.protocol == "MESP" and not out.header.get("reply"):
            # §7.1.1.7: the EyeQ application restarts and judges the sender's E2E rolling
            # counters (D5) afresh, as the simulated EyeQ does; so does a passive observer (a
            # host's counters may start over with its bring-up after this soft reset)
            receiver.e2e.seen.clear()
            if ev.frames:
                receiver.restart_after = ev.frames[-1]
        errors = list(out.errors)
        data_id = out.header.get("data_id") if out.protocol == "DASP" else None
        if data_id is not None:
            counter = out.header["counter"]
            expected = receiver.dasp_counters.check(data_id, counter)
            if expected is not None:
                errors.append(f"DASP counter gap: expected {expected}, got {counter}")
        errors += self._enum_errors(out)
        return {
            "kind": "message", "protocol": out.protocol, "name": out.name,
            "length": len(ev.data), "direction": direction, "time": self.last_time,
            "frames": [receiver.index_of_num.get(n) for n in ev.frames],
            # only MESP carries bytes (byte[] and string parameters); struct fields never do
            "header": out.header,
            "fields": jsonable(out.fields) if out.protocol == "MESP" else out.fields,
            "errors": errors,
        }

    def _enum_errors(self, out: Any) -> list[str]:
        if out.protocol not in ("DASP", "DIAG", "BOOT") or not out.fields or out.errors:
            return []
        msg = self.codec.cat.message(out.name)
        lay = self.codec.layout(msg)
        errs: list[str] = []
        _check_enums(self.codec, lay, out.fields, out.name, errs)
        return errs[:10]


def _replay(conn: TransportConnection, units: list[TransferFrames], restart_span: int) -> None:
    """``conn`` reset to the first frame's NUM (with L10a's ``restart_span``) and fed
    ``units`` again, output dropped."""
    conn.reset(expected=units[0][0][2], restart_span=restart_span)
    for unit in units:
        for data, time_s, _, _ in unit:
            conn.receive_data(data, 0.0 if time_s is None else time_s)
            conn.data_to_send(float("inf"))
    while conn.next_event() is not None:
        pass


_ENUM_PLANS: dict[int, tuple[Any, list[tuple[str, Any, Any, bool]]]] = {}


def _enum_plan(codec: MessageCodec, lay: Any) -> list[tuple[str, Any, Any, bool]]:
    """(member, enum or None, child layout or None, is_array) for the members worth visiting:
    enum-typed scalars and structs that contain one. Cached by layout object (the layout is
    kept with its plan: a new layout reusing a dead one's id() must not get its plan)."""
    key = id(lay)
    hit = _ENUM_PLANS.get(key)
    plan = hit[1] if hit is not None and hit[0] is lay else None
    if plan is None:
        plan = []
        for layout_field in lay.fields:
            child = lay.children.get(layout_field.name)
            if child is not None:
                if _enum_plan(codec, child):
                    plan.append((layout_field.name, None, child, bool(layout_field.count)))
                continue
            enum = codec.cat.enums.get(layout_field.member.enum or "")
            # an incomplete enum (complete: false in specs/) lists only the values the seed
            # lets us read: any other value is not an error
            if (enum is not None and enum.kind != "flags" and enum.complete
                    and not layout_field.count):
                plan.append((layout_field.name, enum, None, False))
        _ENUM_PLANS[key] = (lay, plan)
    return plan


def _check_enums(codec: MessageCodec, lay: Any, values: dict[str, Any], path: str,
                 errs: list[str]) -> None:
    for name, enum, child, is_array in _enum_plan(codec, lay):
        value = values.get(name)
        if child is not None:
            if is_array:
                for index, item in enumerate(value or []):
                    _check_enums(codec, child, item, f"{path}.{name}[{index}]", errs)
            else:
                _check_enums(codec, child, value or {}, f"{path}.{name}", errs)
        elif isinstance(value, int) and value not in enum.values:
            errs.append(f"bad enum value {value} for {path}.{name} ({enum.name})")


def iter_records(transfers: Iterable[Transfer], *, sw: str | None = None,
                 codec: MessageCodec | None = None) -> Iterator[dict[str, Any]]:
    """All records of a capture, in order, ending with the end-of-capture aborts."""
    dis = Dissector(sw, codec)
    for transfer in transfers:
        yield from dis.feed(transfer)
    yield from dis.finish()
