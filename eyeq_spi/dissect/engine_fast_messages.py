"""The messages of a clean span, decoded a group at a time (:mod:`eyeq_spi.codec.message_fast`).

The fast path (:mod:`.engine_fast`) reassembles a block's messages from its arrays; here they
become message records. DASP messages are grouped by (direction, data ID): a group whose every
message has the layout's length is judged at once — E2E CRCs and rolling counters
(:meth:`VecLayout.verify`, D5), undefined enum values (:meth:`VecLayout.enum_errors`) — and its
DASP counters (D1) and fields row by row. 0x41 and 0x10 messages (rule A: an ID byte and one
layout each, no E2E state, no counters) are grouped by (direction, protocol) the same way. Any
other message (MESP, unknown IDs, a group with a wrong length in it) goes to the reference
(:meth:`.engine.Dissector.accept_clean`). The receivers'
state is per (direction, data ID) for DASP (decision D1; E2E counters are keyed by the message's
own layout, and no two DASP messages of a release share one, which the tests check), so groups
are independent and each is judged in capture order: every record is the one the reference
makes (``tests/test_dissect_engine_fast.py`` holds them to it record for record).

``fields`` says what the records of the vectorised groups carry:

- ``"dict"``: the fields as the reference decodes them (the generated ``struct`` path);
- ``"none"`` (``dissect --stats`` and no other output): ``"fields": {}``; everything ``--stats``
  and the filters read is there;
- ``"columns"`` (``--csv``/``--parquet`` with no filter and no other output): ``"fields": {}``,
  and each group's table rows as columns straight from the arrays in :attr:`SpanDecoder.tables`
  (``frame_index``, ``time``, ``direction``, ``header.*``, then the flattened fields, the row a
  :class:`~.output.TableWriter` makes of the reference's record, value for value).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from eyeq_spi.catalog.bringup import SWITCH_APP_NAME
from eyeq_spi.codec.mesp import MESP_PROTOCOL
from eyeq_spi.codec.message import classify
from eyeq_spi.codec.message_fast import vec_layout
from eyeq_spi.dissect.engine import Dissector
from eyeq_spi.errors import SpecError


class SpanMessage:
    """A reassembled message of a span: its direction, bytes, NUMs, transfer ID, time and
    capture indices of its frames (taken when it completed, as the reference takes them)."""

    __slots__ = ("data", "direction", "frames", "nums", "tid", "time")

    def __init__(self, direction: str | None, data: bytes, nums: tuple[int, ...],
                 tid: int | None, time: float | None, frames: list[int | None]) -> None:
        self.direction, self.data, self.nums, self.tid = direction, data, nums, tid
        self.time, self.frames = time, frames


FIELD_MODES = ("dict", "none", "columns")


@dataclass
class ColumnGroup:
    """The table rows of a group's messages: ``first`` is the position (in the block's
    messages) of its first message; ``columns`` in the order of the reference's table row."""

    first: int
    name: str
    columns: dict[str, Any]
    # the records of the group's messages that exist (all of them, or in the lean modes those
    # with errors): their rows are in ``columns``, so a table writer skips them
    covered: list[dict[str, Any]] = field(default_factory=list)


class SpanDecoder:
    def __init__(self, dis: Dissector, *, fields: str = "dict") -> None:
        if fields not in FIELD_MODES:
            raise ValueError(f"fields must be one of {FIELD_MODES}, not {fields!r}")
        self.dis = dis
        self.codec = dis.codec
        self.fields = fields
        self.tables: list[ColumnGroup] = []  # of the last records() call, by first position

    def records(self, msgs: list[SpanMessage]) -> list[dict[str, Any]]:
        """The message records of ``msgs`` (in capture order), in that order."""
        cut = next((i for i, m in enumerate(msgs) if self.is_barrier(m.data)), None)
        if cut is not None:  # the messages before it, it, then the ones after it
            head = self.records(msgs[:cut])
            tables = self.tables
            mid = self.records_reference(msgs[cut : cut + 1])
            tail = self.records(msgs[cut + 1 :])
            for table in self.tables:
                table.first += cut + 1
            self.tables = tables + self.tables
            return head + mid + tail
        out: list[dict[str, Any] | None] = [None] * len(msgs)
        self.tables = []
        groups: dict[tuple[str | None, int | str], list[int]] = {}
        reference: list[int] = []
        for index, msg in enumerate(msgs):
            data = msg.data
            proto = classify(data) if data else "UNKNOWN"
            if proto == "DASP" and len(data) >= 4:
                groups.setdefault((msg.direction, data[1]), []).append(index)
            elif proto in ("DIAG", "BOOT"):  # 0x41 / 0x10: one layout each (rule A)
                groups.setdefault((msg.direction, proto), []).append(index)
            else:
                reference.append(index)
        ids = [k[1] for k in groups]
        for (direction, data_id), rows in groups.items():
            # a data ID in both directions: two groups of one table, rows as dicts
            columns = self.fields == "columns" and ids.count(data_id) == 1
            ok = (self._group(msgs, rows, direction, data_id, out, columns)
                  if isinstance(data_id, int) else
                  self._other(msgs, rows, direction, data_id, out, columns))
            if not ok:
                reference += rows
        if len(self.tables) > 1:
            self.tables.sort(key=lambda g: g.first)
        order = sorted(reference)
        for index, rec in zip(order, self.records_reference([msgs[i] for i in order]),
                              strict=True):
            out[index] = rec
        return out  # type: ignore[return-value]

    def records_reference(self, msgs: list[SpanMessage]) -> list[dict[str, Any]]:
        """The reference's records of ``msgs``, one by one."""
        out = []
        for msg in msgs:
            out.append(self.dis.accept_clean(msg.direction, msg.data, msg.nums, msg.tid, msg.frames,
                                             msg.time))
        return out

    def is_barrier(self, data: bytes) -> bool:
        """A MESP SwitchEyeQApplication request (§7.1.1.1.4): the reference may reset the
        direction's E2E state on it (the application restarts), so no group is judged across
        it: the messages before it, it, and those after it are judged in that order."""
        if len(data) < 5 or data[1] != MESP_PROTOCOL or data[0] != data[2] or data[4] & 0x80:
            return False
        function = self.codec.mesp.functions.get((data[0], data[3]))
        return function is not None and function.name == SWITCH_APP_NAME

    def _rows(self, msgs: list[SpanMessage], rows: list[int], msg: Any, header: int
              ) -> tuple[Any, Any, list[bytes], Any] | None:
        """A group's layout, vectorised layout, message bytes and (rows, header + payload)
        array; None when the group needs the reference (no layout, or a length that is not the
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
        """Judge one (direction, data ID) group at once; False: it needs the reference."""
        msg = self.codec.dasp_message(data_id)
        got = None if msg is None else self._rows(msgs, rows, msg, 4)
        if msg is None or got is None:
            return False
        lay, vl, datas, arr = got
        length = arr.shape[1]
        e2e_state, dasp_counters = self.dis.message_state(direction)
        payloads = arr[:, 4:]
        reserved = arr[:, 3].tolist()
        counters = arr[:, 2].tolist()
        e2e = vl.verify(payloads, e2e_state)
        clean = np.array([not e and not r for e, r in zip(e2e, reserved, strict=True)], bool)
        enums = vl.enum_errors(payloads, msg.name, clean)
        parse = lay.fast.decode if self.fields == "dict" or (
            self.fields == "columns" and not columns) else None
        name = msg.name
        group = None
        if columns:
            group = ColumnGroup(rows[0], name, self._columns(
                *_last_and_times(msgs, rows), direction,
                {"header.data_id": [data_id] * len(rows), "header.counter": counters},
                vl.columns(payloads)))
            self.tables.append(group)
        check = dasp_counters.check
        for position, index in enumerate(rows):
            span_msg = msgs[index]
            counter = counters[position]
            errors = ([f"DASP reserved byte is 0x{reserved[position]:02X}, not 0"]
                      if reserved[position] else [])
            errors += e2e[position]
            expected = check(data_id, counter)
            if expected is not None:
                errors.append(f"DASP counter gap: expected {expected}, got {counter}")
            errors += enums.get(position, ())
            out[index] = {
                "kind": "message", "protocol": "DASP", "name": name, "length": length,
                "direction": direction, "time": span_msg.time, "frames": span_msg.frames,
                "header": {"data_id": data_id, "counter": counter},
                "fields": parse(datas[position][4:]) if parse is not None else {},
                "errors": errors,
            }
        if group is not None:
            group.covered = [out[i] for i in rows]  # type: ignore[misc]
        return True

    def _other(self, msgs: list[SpanMessage], rows: list[int], direction: str | None,
               proto: str, out: list[dict[str, Any] | None], columns: bool) -> bool:
        """A 0x41 (DIAG) or 0x10 (BOOT) group: the ID byte, then the seed's table; no E2E
        state (the engine decodes them without one) and no counters."""
        msg = self.codec.other_message(proto)
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
        group = None
        if columns:
            group = ColumnGroup(rows[0], msg.name, self._columns(
                *_last_and_times(msgs, rows), direction, {"header.id": ids},
                vl.columns(payloads)))
            self.tables.append(group)
        for position, index in enumerate(rows):
            span_msg = msgs[index]
            out[index] = {
                "kind": "message", "protocol": proto, "name": msg.name, "length": length,
                "direction": direction, "time": span_msg.time, "frames": span_msg.frames,
                "header": {"id": ids[position]},
                "fields": parse(datas[position][1:]) if parse is not None else {},
                "errors": e2e[position] + enums.get(position, []),
            }
        if group is not None:
            group.covered = [out[i] for i in rows]  # type: ignore[misc]
        return True

    @staticmethod
    def _columns(last: list[int | None], times: list[float | None], direction: str | None,
                 header: dict[str, list[int]], fields: dict[str, np.ndarray]) -> dict[str, Any]:
        """The TableWriter row of each message as columns: numpy arrays where pyarrow infers
        from them what it infers from the Python values (int64, double), lists elsewhere."""
        count = len(last)
        out: dict[str, Any] = {
            "frame_index": last,
            "time": times,
            "direction": [direction] * count,
            **header,
        }
        for name, col in fields.items():
            kind = col.dtype.kind
            if kind == "f":
                out[name] = col.astype(np.float64)
            elif kind == "i" or (kind == "u" and col.dtype.itemsize < 8):
                out[name] = col.astype(np.int64)
            else:  # uint64: Python ints, as the reference's row has them
                out[name] = col.tolist()
        return out


def _last_and_times(msgs: list[SpanMessage], rows: list[int]
                    ) -> tuple[list[int | None], list[float | None]]:
    return ([msgs[i].frames[-1] if msgs[i].frames else None for i in rows],
            [msgs[i].time for i in rows])
