"""Decoded messages -> MDF4 (asammdf), for asammdf GUI, CANape and the like.

One channel group per message name and direction (``EYEQ_VIS_OBSTACLES_MSG``, ``link h2e``...),
one channel per numeric signal with the flattened name of the dissector's tables
(``visObjects.visObs[3].physicalState.width``), its seed unit, and the seed's enum as a
value-to-text conversion; the master channel is the capture time in seconds. A ``link``
group per direction carries every frame's kind (as a conversion), NUM, RSP and CRC result.
Rows are buffered per group and appended in batches, so memory stays bounded. An input without
times (raw, hex) gets the index of the frame as its time.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect.output import flatten, layout_field, record_layout
from eyeq_spi.errors import MissingExtra, OutputError

FRAME_KINDS = {0: "INVALID", 1: "DATA", 2: "ACK", 3: "NAK"}
_KIND_CODE = {v: k for k, v in FRAME_KINDS.items()}


def need(module: str, what: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtra("export", f"{what} needs {module.split('.')[0]}") from None


class _Group:
    def __init__(self, name: str, comment: str, columns: list[tuple[str, Any, str, Any]]) -> None:
        self.name = name
        self.comment = comment
        self.columns = columns  # (name, dtype, unit, conversion dict or None)
        self.times: list[float] = []
        self.rows: list[list[Any]] = [[] for _ in columns]
        self.index: int | None = None


class MdfWriter:
    def __init__(self, path: str, codec: MessageCodec, *, batch: int = 2000,
                 source: str = "") -> None:
        asammdf = need("asammdf", "--mdf")
        self.asammdf = asammdf
        self.path = path
        self.codec = codec
        self.batch = batch
        self.mdf = asammdf.MDF(version="4.10")
        self.mdf.header.comment = (f"<HDcomment><TX>eyeq-spi export of {source}, SW "
                                   f"{codec.sw}</TX></HDcomment>")
        self.groups: dict[str, _Group] = {}
        self.messages = 0

    # -- layout metadata ------------------------------------------------------------------
    def _columns(self, record: dict[str, Any]) -> list[tuple[str, Any, str, Any]]:
        cols: list[tuple[str, Any, str, Any]] = []
        for name, value, member in _leaves(record["fields"], record_layout(self.codec, record)):
            if isinstance(value, bool):
                dtype: Any = np.uint8
            elif isinstance(value, int):
                dtype = np.int64 if value < 2**63 else np.uint64
            elif isinstance(value, float):
                dtype = np.float64
            else:
                continue  # text and bytes parameters have no place in a numeric channel
            cols.append((name, dtype, *self._meta(member)))
        return cols

    def _meta(self, member: Any) -> tuple[str, Any]:
        if member is None:
            return "", None
        unit = member.units if member.units and member.units not in ("n/a", "NA") else ""
        labels: dict[int, str] = {}
        enum = self.codec.cat.enums.get(member.enum or "")
        if enum is not None and enum.kind != "flags":
            labels = {v: e.name for v, e in enum.values.items()}
        elif member.values:
            labels = dict(member.values)
        return unit, _conversion(labels) if labels else None

    # -- rows ---------------------------------------------------------------------------
    def write(self, record: dict[str, Any]) -> None:
        if record["kind"] == "frame":
            self._frame(record)
        elif record["kind"] == "message" and record["fields"]:
            self._message(record)

    def _frame(self, record: dict[str, Any]) -> None:
        key = f"link {record['direction'] or '-'}"
        group = self.groups.get(key)
        if group is None:
            group = _Group(key, "link frames (L1, L2, L5)", [
                ("frame_type", np.uint8, "", _conversion(FRAME_KINDS)),
                ("NUM", np.int16, "", None), ("RSP", np.int16, "", None),
                ("crc_ok", np.uint8, "", _conversion({0: "CRC BAD", 1: "CRC ok"})),
                ("length", np.int32, "byte", None)])
            self.groups[key] = group
        self._row(group, record["time"], record["index"], [_KIND_CODE.get(record["frame_type"], 0),
                                 -1 if record["num"] is None else record["num"],
                                 -1 if record["rsp"] is None else record["rsp"],
                                 int(record["crc_ok"]), record.get("length", 128)])

    def _message(self, record: dict[str, Any]) -> None:
        key = f"{record['name'] or record['protocol']} {record['direction'] or '-'}"
        group = self.groups.get(key)
        if group is None:
            group = _Group(key, f"{record['protocol']} {record['name']}", self._columns(record))
            self.groups[key] = group
        flat = flatten(record["fields"])
        self.messages += 1
        last = next((f for f in reversed(record["frames"]) if f is not None), 0)
        self._row(group, record["time"], last, [flat.get(c[0], 0) for c in group.columns])

    def _row(self, group: _Group, time: float | None, index: int, values: list[Any]) -> None:
        group.times.append(float(index) if time is None else time)  # no time: the frame index
        for col, value in zip(group.rows, values, strict=True):
            col.append(value if isinstance(value, int | float) else 0)
        if len(group.times) >= self.batch:
            self._flush(group)

    def _flush(self, group: _Group) -> None:
        if not group.times:
            return
        times = np.asarray(group.times, dtype=np.float64)
        data = [np.asarray(col, dtype=dtype)
                for col, (_, dtype, _, _) in zip(group.rows, group.columns, strict=True)]
        if group.index is None:
            signals = [self.asammdf.Signal(samples=d, timestamps=times, name=name, unit=unit,
                                           conversion=conv)
                       for d, (name, _, unit, conv) in zip(data, group.columns, strict=True)]
            if not signals:
                signals = [self.asammdf.Signal(samples=np.zeros(len(times), np.uint8),
                                               timestamps=times, name="present")]
            self.mdf.append(signals, acq_name=group.name, comment=group.comment)
            group.index = len(self.mdf.groups) - 1
        else:
            cols = data or [np.zeros(len(times), np.uint8)]
            self.mdf.extend(group.index, [(times, None), *((d, None) for d in cols)])
        group.times.clear()
        for col in group.rows:
            col.clear()

    def close(self) -> None:
        for group in self.groups.values():
            self._flush(group)
        try:
            self.mdf.save(Path(self.path), overwrite=True)
        except OSError as exc:
            raise OutputError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        finally:
            self.mdf.close()


def _leaves(values: Any, lay: Any, prefix: str = "", member: Any = None
            ) -> Iterator[tuple[str, Any, Any]]:
    """(flattened name, value, layout member or None) of every scalar in ``values``, in the
    order and with the names of :func:`~eyeq_spi.dissect.output.flatten`."""
    if isinstance(values, dict):
        for key, value in values.items():
            field = layout_field(lay, key)
            yield from _leaves(value, lay.children.get(key) if lay is not None else None,
                               f"{prefix}.{key}" if prefix else key,
                               field.member if field is not None else None)
    elif isinstance(values, list):
        for index, item in enumerate(values):
            yield from _leaves(item, lay, f"{prefix}[{index}]", member)
    else:
        yield prefix, values, member


def _conversion(labels: dict[int, str]) -> dict[str, Any]:
    conv: dict[str, Any] = {}
    for index, (value, text) in enumerate(sorted(labels.items())):
        conv[f"val_{index}"] = value
        conv[f"text_{index}"] = text
    return conv
