"""The messages of a batch span, decoded a group at a time (:mod:`eyeq_spi.codec.message_fast`).

The batch dissector (:mod:`.batch`) reassembles a block's messages from its arrays; here they
become message records. DASP messages are grouped by (direction, data ID): a group whose every
message has the layout's length is judged at once — E2E CRCs and rolling counters
(:meth:`VecLayout.verify`, D5), undefined enum values (:meth:`VecLayout.enum_errors`) — and its
DASP counters (D1) and fields row by row. 0x41 and 0x10 messages (rule A: an ID byte and one
layout each, no E2E state, no counters) are grouped by (direction, protocol) the same way. Any
other message (MESP, unknown IDs, a group with a wrong length in it) goes through the exact
engine's ``_message``. The receivers'
state is per (direction, data ID) for DASP (decision D1; E2E counters are keyed by the message's
own layout, and no two DASP messages of a release share one, which the tests check), so groups
are independent and each is judged in capture order: every record is the one the exact engine
makes (``tests/test_dissect_engine_fast.py`` holds them to it record for record).

``fields`` says what the records of the vectorised groups carry:

- ``"dict"``: the fields as the exact engine decodes them (the generated ``struct`` path);
- ``"none"`` (``dissect --stats`` with a filter and no other output): ``"fields": {}``; everything
  ``--stats`` and the filters read is there;
- ``"count"`` (``dissect --stats``, no filter, no other output): *lean*, see below;
- ``"columns"`` (``--csv``/``--parquet`` with no filter and no other output): ``"fields": {}``,
  and each group's table rows as columns straight from the arrays in :attr:`SpanDecoder.tables`
  (``frame_index``, ``time``, ``direction``, ``header.*``, then the flattened fields, the row a
  :class:`~.output.TableWriter` makes of the exact record, value for value). Also lean.

Lean modes (``"count"``, ``"columns"``): the batch dissector cuts a group's messages straight into
an array (:mod:`.engine_fast_cut`) and :meth:`SpanDecoder.lean_group` judges it as :meth:`_group`
would, but makes a record only for a message with an error; the others are one :class:`GroupCount`
(how many, the rows and times of the first and last with a time), which is all ``--stats`` reads of
them (:meth:`.engine_fast_frames.FrameBlock.add_to`). Only plain consumers (no filter) take lean
blocks.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from eyeq_spi.codec.mesp import MESP_PROTOCOL
from eyeq_spi.codec.message import classify
from eyeq_spi.codec.message_fast import vec_layout
from eyeq_spi.dissect.engine import SWITCH_APP, Dissector
from eyeq_spi.errors import SpecError
from eyeq_spi.transport.events import MessageReceived


class SpanMessage:
    """A reassembled message of a span: its direction, bytes, NUMs, transfer ID, time and
    capture indices of its frames (taken when it completed, as the exact engine takes them)."""

    __slots__ = ("data", "direction", "frames", "nums", "tid", "time")

    def __init__(self, direction: str | None, data: bytes, nums: tuple[int, ...],
                 tid: int | None, time: float | None, frames: list[int | None]) -> None:
        self.direction, self.data, self.nums, self.tid = direction, data, nums, tid
        self.time, self.frames = time, frames

    @property
    def ev(self) -> MessageReceived:
        """The transport event the exact engine would have delivered."""
        return MessageReceived(self.data, self.nums, self.tid)


FIELD_MODES = ("dict", "none", "count", "columns")
LEAN_MODES = ("count", "columns")


@dataclass
class GroupCount:
    """A lean group's messages without errors: ``n`` of them; the capture rows (in the chunk)
    and times of the first and the last that have a time (rows -1: none has)."""

    name: str
    n: int
    first_row: int
    t_first: float | None
    last_row: int
    t_last: float | None
    times: list[float]  # of every one with a time: a stream's rate is over its active spans


@dataclass
class ColumnGroup:
    """The table rows of a group's messages: ``first`` is the position (in the block's
    messages) of its first message; ``columns`` in the order of the exact table row."""

    first: int
    name: str
    columns: dict[str, Any]


class SpanDecoder:
    def __init__(self, dis: Dissector, *, fields: str = "dict") -> None:
        if fields not in FIELD_MODES:
            raise ValueError(f"fields must be one of {FIELD_MODES}, not {fields!r}")
        self.dis = dis
        self.codec = dis.codec
        self.fields = fields
        self.tables: list[ColumnGroup] = []  # of the last records() call, by first position
        self.lean = fields in LEAN_MODES

    def records(self, msgs: list[SpanMessage]) -> list[dict[str, Any]]:
        """The message records of ``msgs`` (in capture order), in that order."""
        cut = next((i for i, m in enumerate(msgs) if self.is_barrier(m.data)), None)
        if cut is not None:  # the messages before it, it, then the ones after it
            head = self.records(msgs[:cut])
            tables = self.tables
            mid = self.records_exact(msgs[cut : cut + 1])
            tail = self.records(msgs[cut + 1 :])
            for g in self.tables:
                g.first += cut + 1
            self.tables = tables + self.tables
            return head + mid + tail
        out: list[dict[str, Any] | None] = [None] * len(msgs)
        self.tables = []
        groups: dict[tuple[str | None, int | str], list[int]] = {}
        exact: list[int] = []
        for i, m in enumerate(msgs):
            data = m.data
            proto = classify(data) if data else "UNKNOWN"
            if proto == "DASP" and len(data) >= 4:
                groups.setdefault((m.direction, data[1]), []).append(i)
            elif proto in ("DIAG", "BOOT"):  # 0x41 / 0x10: one layout each (rule A)
                groups.setdefault((m.direction, proto), []).append(i)
            else:
                exact.append(i)
        ids = [k[1] for k in groups]
        for (direction, data_id), rows in groups.items():
            # a data ID in both directions: two groups of one table, rows as dicts
            columns = self.fields == "columns" and ids.count(data_id) == 1
            ok = (self._group(msgs, rows, direction, data_id, out, columns)
                  if isinstance(data_id, int) else
                  self._other(msgs, rows, direction, data_id, out, columns))
            if not ok:
                exact += rows
        if len(self.tables) > 1:
            self.tables.sort(key=lambda g: g.first)
        for i, rec in zip(sorted(exact), self.records_exact([msgs[i] for i in sorted(exact)]),
                          strict=True):
            out[i] = rec
        return out  # type: ignore[return-value]

    def records_exact(self, msgs: list[SpanMessage]) -> list[dict[str, Any]]:
        """The exact engine's records of ``msgs``, one by one."""
        out = []
        for m in msgs:
            self.dis.last_time = m.time
            rec = self.dis._message(m.direction, self.dis._dirs[m.direction], m.ev)
            rec["frames"] = m.frames
            out.append(rec)
        return out

    def is_barrier(self, data: bytes) -> bool:
        """A MESP SwitchEyeQApplication request (§7.1.1.1.4): the exact engine may reset the
        direction's E2E state on it (the application restarts), so no group is judged across
        it: the messages before it, it, and those after it are judged in that order."""
        if len(data) < 5 or data[1] != MESP_PROTOCOL or data[0] != data[2] or data[4] & 0x80:
            return False
        f = self.codec.mesp.functions.get((data[0], data[3]))
        return f is not None and f.name == SWITCH_APP

    def _rows(self, msgs: list[SpanMessage], rows: list[int], msg: Any, header: int
              ) -> tuple[Any, Any, list[bytes], Any] | None:
        """A group's layout, vectorised layout, message bytes and (rows, header + payload)
        array; None when the group needs the exact path (no layout, or a length that is not the
        layout's)."""
        try:
            lay = self.codec.layout(msg)
        except SpecError:
            return None
        length = header + lay.size
        datas = [msgs[i].data for i in rows]
        if any(len(x) != length for x in datas):
            return None
        arr = np.frombuffer(b"".join(datas), np.uint8).reshape(len(rows), length)
        return lay, vec_layout(lay, self.codec.cat), datas, arr

    def _group(self, msgs: list[SpanMessage], rows: list[int], direction: str | None,
               data_id: int, out: list[dict[str, Any] | None], columns: bool) -> bool:
        """Judge one (direction, data ID) group at once; False: it needs the exact path."""
        msg = self.codec.dasp_message(data_id)
        got = None if msg is None else self._rows(msgs, rows, msg, 4)
        if msg is None or got is None:
            return False
        lay, vl, datas, arr = got
        length = arr.shape[1]
        d = self.dis._dirs[direction]
        payloads = arr[:, 4:]
        reserved = arr[:, 3].tolist()
        counters = arr[:, 2].tolist()
        e2e = vl.verify(payloads, d.e2e)
        clean = np.array([not e and not r for e, r in zip(e2e, reserved, strict=True)], bool)
        enums = vl.enum_errors(payloads, msg.name, clean)
        parse = lay.fast.decode if self.fields == "dict" or (
            self.fields == "columns" and not columns) else None
        name = msg.name
        if columns:
            self.tables.append(ColumnGroup(rows[0], name, self._columns(
                *_last_and_times(msgs, rows), direction,
                {"header.data_id": [data_id] * len(rows), "header.counter": counters},
                vl.columns(payloads))))
        check = d.dasp_counters.check
        for k, i in enumerate(rows):
            m = msgs[i]
            counter = counters[k]
            errors = [f"DASP reserved byte is 0x{reserved[k]:02X}, not 0"] if reserved[k] else []
            errors += e2e[k]
            expected = check(data_id, counter)
            if expected is not None:
                errors.append(f"DASP counter gap: expected {expected}, got {counter}")
            errors += enums.get(k, ())
            out[i] = {
                "kind": "message", "protocol": "DASP", "name": name, "length": length,
                "direction": direction, "time": m.time, "frames": m.frames,
                "header": {"data_id": data_id, "counter": counter},
                "fields": parse(datas[k][4:]) if parse is not None else {},
                "errors": errors,
            }
        return True

    def _other(self, msgs: list[SpanMessage], rows: list[int], direction: str | None,
               proto: str, out: list[dict[str, Any] | None], columns: bool) -> bool:
        """A 0x41 (DIAG) or 0x10 (BOOT) group: the ID byte, then the seed's table; no E2E
        state (the engine decodes them without one) and no counters."""
        msg = self.codec._other.get(proto)
        got = None if msg is None else self._rows(msgs, rows, msg, 1)
        if msg is None or got is None:
            return False
        lay, vl, datas, arr = got
        length = arr.shape[1]
        payloads = arr[:, 1:]
        ids = arr[:, 0].tolist()
        e2e = vl.verify(payloads, None)
        enums = vl.enum_errors(payloads, msg.name, np.array([not e for e in e2e], bool))
        parse = lay.fast.decode if self.fields == "dict" or (
            self.fields == "columns" and not columns) else None
        if columns:
            self.tables.append(ColumnGroup(rows[0], msg.name, self._columns(
                *_last_and_times(msgs, rows), direction, {"header.id": ids},
                vl.columns(payloads))))
        for k, i in enumerate(rows):
            m = msgs[i]
            out[i] = {
                "kind": "message", "protocol": proto, "name": msg.name, "length": length,
                "direction": direction, "time": m.time, "frames": m.frames,
                "header": {"id": ids[k]},
                "fields": parse(datas[k][1:]) if parse is not None else {},
                "errors": e2e[k] + enums.get(k, []),
            }
        return True

    @staticmethod
    def _columns(last: list[int | None], times: list[float | None], direction: str | None,
                 header: dict[str, list[int]], fields: dict[str, np.ndarray]) -> dict[str, Any]:
        """The TableWriter row of each message as columns: numpy arrays where pyarrow infers
        from them what it infers from the Python values (int64, double), lists elsewhere."""
        n = len(last)
        out: dict[str, Any] = {
            "frame_index": last,
            "time": times,
            "direction": [direction] * n,
            **header,
        }
        for k, col in fields.items():
            kind = col.dtype.kind
            if kind == "f":
                out[k] = col.astype(np.float64)
            elif kind == "i" or (kind == "u" and col.dtype.itemsize < 8):
                out[k] = col.astype(np.int64)
            else:  # uint64: Python ints, as the exact row has them
                out[k] = col.tolist()
        return out

    # -- lean modes ----------------------------------------------------------------------------
    def lean_group(self, direction: str | None, key: int | str, arr: np.ndarray,
                   rows: list[int], times: np.ndarray, last: list[int | None],
                   frames_of: Callable[[int], list[int | None]], columns: bool
                   ) -> tuple[list[tuple[int, dict[str, Any]]], GroupCount | None,
                              ColumnGroup | None] | None:
        """A (direction, data ID) DASP group (``key`` an int) or a 0x41/0x10 group (``key``
        "DIAG"/"BOOT") whose messages are the rows of ``arr`` (header + payload), completed at
        chunk ``rows`` with ``times`` (NaN: none) and ``last`` frame indices; ``frames_of(k)``:
        row k's frame indices. The records of the messages with errors (as :meth:`_group` /
        :meth:`_other` make them, ``"fields": {}``) with their rows, the count of the others,
        and with ``columns`` every message's table row. None: the group needs the exact path."""
        dasp = isinstance(key, int)
        msg = self.codec.dasp_message(key) if isinstance(key, int) else self.codec._other.get(key)
        hdr = 4 if dasp else 1
        if msg is None:
            return None
        try:
            lay = self.codec.layout(msg)
        except SpecError:
            return None
        n, length = arr.shape
        if length != hdr + lay.size or not n:
            return None
        vl = vec_layout(lay, self.codec.cat)
        payloads = arr[:, hdr:]
        name = msg.name
        d = self.dis._dirs[direction]
        e2e = vl.verify(payloads, d.e2e if dasp else None)
        clean = ~np.fromiter(map(bool, e2e), bool, n)
        head: dict[str, list[int]]
        if isinstance(key, int):
            reserved = arr[:, 3]
            clean &= reserved == 0
            counters = arr[:, 2].astype(np.int64)
            # D1: each counter against the one before it (the receiver's last for row 0)
            dc = d.dasp_counters
            before = dc.last(key)
            prev = np.empty(n, np.int64)
            prev[0] = -1 if before is None else before
            prev[1:] = counters[:-1]
            expected = (prev + 1) & 0xFF
            gap = (prev >= 0) & (counters != expected)
            dc.learn(key, int(counters[-1]))
            bad = ~clean | gap
            head = {"header.data_id": [key] * n, "header.counter": counters.tolist()}
        else:
            bad = ~clean
            head = {"header.id": arr[:, 0].tolist()}
        enums = vl.enum_errors(payloads, name, clean)
        if enums:
            bad[list(enums)] = True
        proto = "DASP" if dasp else str(key)
        recs: list[tuple[int, dict[str, Any]]] = []
        for k in np.flatnonzero(bad).tolist():
            t = float(times[k])
            if dasp:
                counter = head["header.counter"][k]
                r = int(reserved[k])
                errors = [f"DASP reserved byte is 0x{r:02X}, not 0"] if r else []
                errors += e2e[k]
                if gap[k]:
                    errors.append(f"DASP counter gap: expected {int(expected[k])}, got {counter}")
                header: dict[str, int] = {"data_id": key, "counter": counter}  # type: ignore[dict-item]
            else:
                errors = list(e2e[k])
                header = {"id": head["header.id"][k]}
            errors += enums.get(k, ())
            recs.append((rows[k], {
                "kind": "message", "protocol": proto, "name": name, "length": length,
                "direction": direction, "time": None if t != t else t, "frames": frames_of(k),
                "header": header, "fields": {}, "errors": errors,
            }))
        count = None
        ok = ~bad
        if ok.any():
            timed = np.flatnonzero(ok & ~np.isnan(times))
            lo, hi = (int(timed[0]), int(timed[-1])) if timed.size else (-1, -1)
            count = GroupCount(name, int(ok.sum()), rows[lo] if lo >= 0 else -1,
                               float(times[lo]) if lo >= 0 else None,
                               rows[hi] if hi >= 0 else -1,
                               float(times[hi]) if hi >= 0 else None, times[timed].tolist())
        table = None
        if columns:
            tl = times.tolist()
            table = ColumnGroup(rows[0], name, self._columns(
                last, [None if t != t else t for t in tl], direction, head,
                vl.columns(payloads)))
        return recs, count, table


def _last_and_times(msgs: list[SpanMessage], rows: list[int]
                    ) -> tuple[list[int | None], list[float | None]]:
    return ([msgs[i].frames[-1] if msgs[i].frames else None for i in rows],
            [msgs[i].time for i in rows])
