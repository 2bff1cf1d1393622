"""The messages of a batch span, decoded a group at a time (:mod:`eyeq_spi.codec.vdecode`).

The batch dissector (:mod:`.batch`) reassembles a block's messages from its arrays; here they
become message records. DASP messages are grouped by (direction, data ID): a group whose every
message has the layout's length is judged at once — E2E CRCs and rolling counters
(:meth:`VecLayout.verify`, D5), undefined enum values (:meth:`VecLayout.enum_errors`) — and its
DASP counters (D1) and fields row by row; any other message (MESP, 0x41, 0x10, unknown IDs,
a group with a wrong length in it) goes through the exact engine's ``_message``. The receivers'
state is per (direction, data ID) for DASP (decision D1; E2E counters are keyed by the message's
own layout, and no two DASP messages of a release share one, which the tests check), so groups
are independent and each is judged in capture order: every record is the one the exact engine
makes (``tests/test_batch.py`` holds them to it record for record).

``fields=False`` (``dissect --stats`` with no other output): DASP records of the vectorised
groups carry ``"fields": {}``; everything ``--stats`` and the filters read is there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from eyeq_spi.codec.message import DASP_PROTOCOL, classify
from eyeq_spi.codec.vdecode import vec_layout
from eyeq_spi.dissect.engine import Dissector
from eyeq_spi.errors import SpecError
from eyeq_spi.transport.events import MessageReceived


@dataclass
class SpanMessage:
    """A reassembled message of a span: its direction, time and capture indices of its frames
    (taken when it completed, as the exact engine takes them)."""

    direction: str | None
    ev: MessageReceived
    time: float | None
    frames: list[int | None]


class SpanDecoder:
    def __init__(self, dis: Dissector, *, fields: bool = True) -> None:
        self.dis = dis
        self.codec = dis.codec
        self.fields = fields

    def records(self, msgs: list[SpanMessage]) -> list[dict[str, Any]]:
        """The message records of ``msgs`` (in capture order), in that order."""
        out: list[dict[str, Any] | None] = [None] * len(msgs)
        groups: dict[tuple[str | None, int], list[int]] = {}
        exact: list[int] = []
        for i, m in enumerate(msgs):
            data = m.ev.data
            if len(data) >= 4 and data[0] == DASP_PROTOCOL and classify(data) == "DASP":
                groups.setdefault((m.direction, data[1]), []).append(i)
            else:
                exact.append(i)
        for (direction, data_id), rows in groups.items():
            if not self._group(msgs, rows, direction, data_id, out):
                exact += rows
        for i in sorted(exact) if len(exact) > 1 else exact:
            m = msgs[i]
            self.dis.last_time = m.time
            rec = self.dis._message(m.direction, self.dis._dirs[m.direction], m.ev)
            rec["frames"] = m.frames
            out[i] = rec
        return out  # type: ignore[return-value]

    def _group(self, msgs: list[SpanMessage], rows: list[int], direction: str | None,
               data_id: int, out: list[dict[str, Any] | None]) -> bool:
        """Judge one (direction, data ID) group at once; False: it needs the exact path."""
        codec = self.codec
        msg = codec.dasp_message(data_id)
        if msg is None:
            return False
        try:
            lay = codec.layout(msg)
        except SpecError:
            return False
        length = 4 + lay.size
        datas = [msgs[i].ev.data for i in rows]
        if any(len(x) != length for x in datas):
            return False
        vl = vec_layout(lay, codec.cat)
        d = self.dis._dirs[direction]
        arr = np.frombuffer(b"".join(datas), np.uint8).reshape(len(rows), length)
        payloads = arr[:, 4:]
        reserved = arr[:, 3].tolist()
        counters = arr[:, 2].tolist()
        e2e = vl.verify(payloads, d.e2e)
        clean = np.array([not e and not r for e, r in zip(e2e, reserved, strict=True)], bool)
        enums = vl.enum_errors(payloads, msg.name, clean)
        parse = lay.fast.decode if self.fields else None
        name = msg.name
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
