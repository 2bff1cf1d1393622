"""The messages of a clean span, decoded a group at a time (:mod:`eyeq_spi.codec.message_fast`).

DASP messages are grouped by (direction, data ID), 0x41 and 0x10 ones by (direction,
protocol) (rule A: an ID byte and one layout each, no E2E state, no counters). A group whose
every message has the layout's length is judged at once (E2E, D5; enum values) and its DASP
counters (D1) and fields row by row; any other message goes to
:meth:`.engine.Dissector.accept_clean`. The state is per (direction, data ID) (D1; no two DASP
messages of a release share a layout), so each group is judged in capture order and every
record is the reference's.

``fields`` says what the records of the vectorised groups carry: ``"dict"`` the fields,
``"none"`` (``--stats`` alone) none, ``"columns"`` (one table writer, no filter) none, with
each group's table rows as columns in :attr:`SpanDecoder.tables`.
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


@dataclass(slots=True)
class SpanMessage:
    """A reassembled message of a span, with the capture indices of its frames."""

    direction: str | None
    data: bytes
    nums: tuple[int, ...]
    tid: int | None
    time: float | None
    frames: list[int | None]


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
            if not self._group(msgs, rows, direction, data_id, out, columns):
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
        return [self.dis.accept_clean(msg.direction, msg.data, msg.nums, msg.tid, msg.frames,
                                      msg.time) for msg in msgs]

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
               key: int | str, out: list[dict[str, Any] | None], columns: bool) -> bool:
        """Judge one group at once: a (direction, DASP data ID) group, or a (direction,
        "DIAG"/"BOOT") one (the ID byte, then the seed's table; no E2E state, no counters).
        False: it needs the reference."""
        if isinstance(key, int):
            data_id: int | None = key
            msg, header_size = self.codec.dasp_message(key), 4
        else:
            data_id = None
            msg, header_size = self.codec.other_message(key), 1
        dasp = data_id is not None
        got = None if msg is None else self._rows(msgs, rows, msg, header_size)
        if msg is None or got is None:
            return False
        lay, vl, datas, arr = got
        length = arr.shape[1]
        payloads = arr[:, header_size:]
        e2e_state, dasp_counters = self.dis.message_state(direction) if dasp else (None, None)
        counters = arr[:, 2].tolist() if dasp else []
        reserved = arr[:, 3].tolist() if dasp else [0] * len(rows)
        ids = [] if dasp else arr[:, 0].tolist()
        e2e = vl.verify(payloads, e2e_state)
        clean = np.array([not e and not r for e, r in zip(e2e, reserved, strict=True)], bool)
        enums = vl.enum_errors(payloads, msg.name, clean)
        parse = lay.fast.decode if self.fields == "dict" or (
            self.fields == "columns" and not columns) else None
        name, protocol = msg.name, "DASP" if dasp else key
        group = None
        if columns:
            header = ({"header.data_id": [key] * len(rows), "header.counter": counters} if dasp
                      else {"header.id": ids})
            group = ColumnGroup(rows[0], name, self._columns(msgs, rows, direction, header,
                                                             vl.columns(payloads)))
            self.tables.append(group)
        for position, index in enumerate(rows):
            span_msg = msgs[index]
            errors = ([f"DASP reserved byte is 0x{reserved[position]:02X}, not 0"]
                      if reserved[position] else [])
            errors += e2e[position]
            if data_id is not None and dasp_counters is not None:
                counter = counters[position]
                expected = dasp_counters.check(data_id, counter)
                if expected is not None:
                    errors.append(f"DASP counter gap: expected {expected}, got {counter}")
            errors += enums.get(position, ())
            out[index] = {
                "kind": "message", "protocol": protocol, "name": name, "length": length,
                "direction": direction, "time": span_msg.time, "frames": span_msg.frames,
                "header": ({"data_id": key, "counter": counters[position]} if dasp
                           else {"id": ids[position]}),
                "fields": parse(datas[position][header_size:]) if parse is not None else {},
                "errors": errors,
            }
        if group is not None:
            group.covered = [out[i] for i in rows]  # type: ignore[misc]
        return True

    @staticmethod
    def _columns(msgs: list[SpanMessage], rows: list[int], direction: str | None,
                 header: dict[str, Any], fields: dict[str, np.ndarray]) -> dict[str, Any]:
        """The TableWriter row of each message as columns: numpy arrays where pyarrow infers
        from them what it infers from the Python values (int64, double), lists elsewhere."""
        out: dict[str, Any] = {
            "frame_index": [msgs[i].frames[-1] if msgs[i].frames else None for i in rows],
            "time": [msgs[i].time for i in rows],
            "direction": [direction] * len(rows),
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

