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

from pathlib import Path
from typing import Any

import numpy as np

from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect.output import flatten
from eyeq_spi.errors import EyeqError, MissingExtra, OutputError

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
    def _columns(self, r: dict[str, Any]) -> list[tuple[str, Any, str, Any]]:
        info: dict[str, tuple[str, Any]] = {}
        lay = None
        if r["protocol"] in ("DASP", "DIAG", "BOOT") and r["name"]:
            try:
                lay = self.codec.layout(self.codec.cat.message(r["name"]))
            except EyeqError:
                lay = None
        self._walk(r["fields"], lay, "", info)
        cols: list[tuple[str, Any, str, Any]] = []
        for name, value in flatten(r["fields"]).items():
            if isinstance(value, bool):
                dtype: Any = np.uint8
            elif isinstance(value, int):
                dtype = np.int64 if value < 2**63 else np.uint64
            elif isinstance(value, float):
                dtype = np.float64
            else:
                continue  # text and bytes parameters have no place in a numeric channel
            unit, conv = info.get(name, ("", None))
            cols.append((name, dtype, unit, conv))
        return cols

    def _walk(self, values: Any, lay: Any, prefix: str, out: dict[str, tuple[str, Any]]) -> None:
        if not isinstance(values, dict):
            return
        for k, v in values.items():
            name = f"{prefix}.{k}" if prefix else k
            child = lay.children.get(k) if lay is not None else None
            try:
                member = lay.field(k).member if lay is not None else None
            except KeyError:
                member = None
            if isinstance(v, dict):
                self._walk(v, child, name, out)
            elif isinstance(v, list):
                for i, item in enumerate(v):
                    if isinstance(item, dict):
                        self._walk(item, child, f"{name}[{i}]", out)
                    else:
                        out[f"{name}[{i}]"] = self._meta(member)
            else:
                out[name] = self._meta(member)

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
    def write(self, r: dict[str, Any]) -> None:
        if r["kind"] == "frame":
            self._frame(r)
        elif r["kind"] == "message" and r["fields"]:
            self._message(r)

    def _frame(self, r: dict[str, Any]) -> None:
        key = f"link {r['direction'] or '-'}"
        g = self.groups.get(key)
        if g is None:
            g = _Group(key, "link frames (L1, L2, L5)", [
                ("frame_type", np.uint8, "", _conversion(FRAME_KINDS)),
                ("NUM", np.int16, "", None), ("RSP", np.int16, "", None),
                ("crc_ok", np.uint8, "", _conversion({0: "CRC BAD", 1: "CRC ok"})),
                ("length", np.int32, "byte", None)])
            self.groups[key] = g
        self._row(g, r["time"], r["index"], [_KIND_CODE.get(r["frame_type"], 0),
                                 -1 if r["num"] is None else r["num"],
                                 -1 if r["rsp"] is None else r["rsp"],
                                 int(r["crc_ok"]), r.get("length", 128)])

    def _message(self, r: dict[str, Any]) -> None:
        key = f"{r['name'] or r['protocol']} {r['direction'] or '-'}"
        g = self.groups.get(key)
        if g is None:
            g = _Group(key, f"{r['protocol']} {r['name']}", self._columns(r))
            self.groups[key] = g
        flat = flatten(r["fields"])
        self.messages += 1
        last = next((f for f in reversed(r["frames"]) if f is not None), 0)
        self._row(g, r["time"], last, [flat.get(c[0], 0) for c in g.columns])

    def _row(self, g: _Group, time: float | None, index: int, values: list[Any]) -> None:
        g.times.append(float(index) if time is None else time)  # no time: the frame index
        for col, v in zip(g.rows, values, strict=True):
            col.append(v if isinstance(v, int | float) else 0)
        if len(g.times) >= self.batch:
            self._flush(g)

    def _flush(self, g: _Group) -> None:
        if not g.times:
            return
        t = np.asarray(g.times, dtype=np.float64)
        data = [np.asarray(col, dtype=dtype) for col, (_, dtype, _, _) in zip(g.rows, g.columns,
                                                                               strict=True)]
        if g.index is None:
            signals = [self.asammdf.Signal(samples=d, timestamps=t, name=name, unit=unit,
                                           conversion=conv)
                       for d, (name, _, unit, conv) in zip(data, g.columns, strict=True)]
            if not signals:
                signals = [self.asammdf.Signal(samples=np.zeros(len(t), np.uint8),
                                               timestamps=t, name="present")]
            self.mdf.append(signals, acq_name=g.name, comment=g.comment)
            g.index = len(self.mdf.groups) - 1
        else:
            cols = data or [np.zeros(len(t), np.uint8)]
            self.mdf.extend(g.index, [(t, None), *((d, None) for d in cols)])
        g.times.clear()
        for col in g.rows:
            col.clear()

    def close(self) -> None:
        for g in self.groups.values():
            self._flush(g)
        try:
            self.mdf.save(Path(self.path), overwrite=True)
        except OSError as exc:
            raise OutputError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        finally:
            self.mdf.close()


def _conversion(labels: dict[int, str]) -> dict[str, Any]:
    conv: dict[str, Any] = {}
    for i, (value, text) in enumerate(sorted(labels.items())):
        conv[f"val_{i}"] = value
        conv[f"text_{i}"] = text
    return conv
