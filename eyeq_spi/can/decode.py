"""Decoding CAN logs (BLF, ASC, candump, TRC, MF4 through python-can's readers) with the DBCs
built from ``specs/can/``, into the record shape of ``eyeq-spi dissect --json``, and the
statistics of ``--stats`` (cycle time per ID against the spec, invalid and out-of-range values).

A record is ``{"kind": "message", "protocol": "CAN", "name", "length", "direction": null,
"time", "frames": [index], "header": {"id", "channel"}, "fields": {signal: physical},
"labels": {signal: enum label}, "invalid": [signals at their invalid value], "errors": [...]}``;
``errors`` lists an unknown ID, a DLC that is not the spec's and values outside a signal's range.
"""

from __future__ import annotations

import math
import statistics
from collections import Counter, defaultdict
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from eyeq_spi.can.dbc import database, require_cantools
from eyeq_spi.errors import EyeqError
from eyeq_spi.spec.can import CanMessage, CanSignal, protocol

READ_SUFFIXES = (".blf", ".asc", ".log", ".trc", ".mf4", ".csv")


class CanLogError(EyeqError):
    """A CAN log cannot be read (missing, unknown format, corrupt)."""


def read_log(path: str) -> Iterator[Any]:
    """python-can messages of one log file, in file order."""
    require_cantools()
    import can

    p = Path(path)
    if p.suffix.lower() not in READ_SUFFIXES:
        raise CanLogError(f"{path}: unknown CAN log format {p.suffix!r} "
                          f"(one of {', '.join(READ_SUFFIXES)})")
    if not p.is_file():
        raise CanLogError(f"{path}: no such file")
    try:
        reader = can.LogReader(str(p))
    except ImportError as exc:
        raise CanLogError(f"{path}: this format needs {exc.name or exc} "
                          "(pip install asammdf for .mf4)") from exc
    except Exception as exc:  # python-can raises many kinds on a foreign file
        raise CanLogError(f"{path}: not a readable {p.suffix} CAN log: {exc}") from exc
    try:
        yield from reader
    except EyeqError:
        raise
    except Exception as exc:  # truncated or corrupt content
        raise CanLogError(f"{path}: corrupt {p.suffix} CAN log: {exc}") from exc
    finally:
        stop = getattr(reader, "stop", None)
        if callable(stop):
            stop()


@dataclass
class _Sig:
    spec: CanSignal
    db: Any  # cantools Signal


class CanDecoder:
    """Decodes python-can messages of one protocol with its generated database."""

    def __init__(self, proto: str) -> None:
        self.protocol = protocol(proto)
        self.db = database(self.protocol.name)
        self._by_id: dict[int, tuple[CanMessage, Any, list[_Sig]]] = {}
        for m in self.protocol.messages:
            for _, fid, _ in m.instances():
                dbm = self.db.get_message_by_frame_id(fid)
                sigs = [_Sig(s, dbm.get_signal_by_name(s.name)) for s in m.signals]
                self._by_id[fid] = (m, dbm, sigs)

    def spec_for(self, frame_id: int) -> CanMessage | None:
        hit = self._by_id.get(frame_id)
        return hit[0] if hit else None

    def decode(self, msg: Any, index: int) -> dict[str, Any]:
        fid = int(msg.arbitration_id)
        data = bytes(msg.data)
        rec: dict[str, Any] = {
            "kind": "message", "protocol": "CAN", "name": None, "length": len(data),
            "direction": None, "time": float(msg.timestamp), "frames": [index],
            "header": {"id": fid, "channel": None if msg.channel is None else str(msg.channel)},
            "fields": {}, "labels": {}, "invalid": [], "errors": [],
        }
        hit = self._by_id.get(fid) if not msg.is_extended_id else None
        if hit is None:
            rec["errors"].append(f"unknown ID 0x{fid:X}")
            return rec
        spec, dbm, sigs = hit
        rec["name"] = dbm.name
        if len(data) != spec.dlc:
            rec["errors"].append(f"DLC {len(data)}, spec {spec.dlc}")
            # decode what is there
            data = (data + bytes(max(spec.dlc - len(data), 0)))[:spec.dlc]
        try:
            raw = dbm.decode(data, decode_choices=False, scaling=False)
        except Exception as exc:  # cantools on a malformed payload
            rec["errors"].append(f"undecodable: {exc}")
            return rec
        for s in sigs:
            r = raw.get(s.spec.name)
            if r is None:
                continue
            value = s.db.conversion.raw_to_scaled(r, decode_choices=False)
            if isinstance(value, float) and not math.isfinite(value):
                value = None
            rec["fields"][s.spec.name] = value
            if s.spec.enum:
                label = self.protocol.enums[s.spec.enum].get(int(r))
                rec["labels"][s.spec.name] = label
            if s.spec.raw_invalid is not None and r == s.spec.raw_invalid:
                rec["invalid"].append(s.spec.name)
            elif value is not None and (
                    (s.spec.min is not None and value < s.spec.min - 1e-9 * abs(s.spec.min))
                    or (s.spec.max is not None and value > s.spec.max + 1e-9 * abs(s.spec.max))):
                rec["errors"].append(f"{s.spec.name} {value:g} outside "
                                     f"[{s.spec.min:g}, {s.spec.max:g}]")
        return rec


@dataclass
class _IdStats:
    name: str | None
    count: int = 0
    last: float | None = None
    intervals: list[float] = field(default_factory=list)


class CanStats:
    """Streaming statistics: frames per ID, cycle time against the spec, value problems."""

    MAX_INTERVALS = 100_000  # per ID: memory stays bounded whatever the log size

    def __init__(self, decoder: CanDecoder) -> None:
        self.decoder = decoder
        self.frames = 0
        self.ids: dict[int, _IdStats] = {}
        self.unknown: Counter[int] = Counter()
        self.dlc_errors: Counter[str] = Counter()
        self.invalid: defaultdict[str, Counter[str]] = defaultdict(Counter)
        self.out_of_range: defaultdict[str, Counter[str]] = defaultdict(Counter)
        self.first: float | None = None
        self.last: float | None = None

    def add(self, rec: dict[str, Any]) -> None:
        self.frames += 1
        t, fid, name = rec["time"], rec["header"]["id"], rec["name"]
        self.first = t if self.first is None else min(self.first, t)
        self.last = t if self.last is None else max(self.last, t)
        if name is None:
            self.unknown[fid] += 1
            return
        st = self.ids.setdefault(fid, _IdStats(name))
        st.count += 1
        if st.last is not None and len(st.intervals) < self.MAX_INTERVALS:
            st.intervals.append(t - st.last)
        st.last = t
        for s in rec["invalid"]:
            self.invalid[name][s] += 1
        for e in rec["errors"]:
            if e.startswith("DLC"):
                self.dlc_errors[name] += 1
            elif " outside " in e:
                self.out_of_range[name][e.split(" ", 1)[0]] += 1

    def result(self) -> dict[str, Any]:
        per_id = []
        for fid, st in sorted(self.ids.items()):
            spec = self.decoder.spec_for(fid)
            cyc = spec.cycle_ms if spec else None
            med = statistics.median(st.intervals) * 1000 if st.intervals else None
            mean = statistics.fmean(st.intervals) * 1000 if st.intervals else None
            per_id.append({
                "id": fid, "name": st.name, "frames": st.count, "spec_cycle_ms": cyc,
                "median_cycle_ms": None if med is None else round(med, 3),
                "mean_cycle_ms": None if mean is None else round(mean, 3),
                "cycle_deviation_pct": None if med is None or not cyc
                else round(100.0 * (med - cyc) / cyc, 2),
                "invalid": dict(self.invalid.get(st.name or "", {})),
                "out_of_range": dict(self.out_of_range.get(st.name or "", {})),
                "dlc_errors": self.dlc_errors.get(st.name or "", 0),
            })
        return {"kind": "stats", "protocol": self.decoder.protocol.name, "frames": self.frames,
                "duration_s": None if self.first is None or self.last is None
                else round(self.last - self.first, 6),
                "unknown_ids": {f"0x{k:X}": v for k, v in sorted(self.unknown.items())},
                "invalid_values": sum(sum(c.values()) for c in self.invalid.values()),
                "out_of_range_values": sum(sum(c.values()) for c in self.out_of_range.values()),
                "ids": per_id}


def human_stats(s: dict[str, Any]) -> str:
    lines = [f"{s['frames']} frames over {s['duration_s']} s, protocol {s['protocol']}; "
             f"unknown IDs {s['unknown_ids'] or 'none'}; invalid values {s['invalid_values']}, "
             f"out of range {s['out_of_range_values']}",
             f"{'ID':>6s} {'message':30s} {'frames':>7s} {'cycle ms':>9s} {'spec':>6s} "
             f"{'dev %':>7s}  invalid / out of range"]
    for r in s["ids"]:
        med = "-" if r["median_cycle_ms"] is None else f"{r['median_cycle_ms']:.1f}"
        dev = "-" if r["cycle_deviation_pct"] is None else f"{r['cycle_deviation_pct']:+.1f}"
        probs = ", ".join([f"{k} invalid x{v}" for k, v in r["invalid"].items()]
                          + [f"{k} out of range x{v}" for k, v in r["out_of_range"].items()])
        lines.append(f"0x{r['id']:04X} {r['name']:30s} {r['frames']:7d} {med:>9s} "
                     f"{r['spec_cycle_ms']!s:>6s} {dev:>7s}  {probs}")
    return "\n".join(lines)


def human_record(r: dict[str, Any]) -> str:
    t = "-" if r["time"] is None else f"{r['time']:.6f}"
    head = f"{r['frames'][0]:8d} {t:>14s} 0x{r['header']['id']:03X} {r['name'] or '?':24s}"
    parts = []
    for k, v in r["fields"].items():
        text = f"{v:.6g}" if isinstance(v, float) else str(v)
        label = r["labels"].get(k)
        if label:
            text += f" ({label})"
        if k in r["invalid"]:
            text += " (invalid)"
        parts.append(f"{k}={text}")
    errs = f"  !! {'; '.join(r['errors'])}" if r["errors"] else ""
    return f"{head} {' '.join(parts)}{errs}"
