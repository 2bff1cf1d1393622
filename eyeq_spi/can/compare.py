"""``eyeq-spi can compare OTHER.dbc``: a user's (vendor's, public) DBC against the DBC built from
``specs/can/``, message by message and signal by signal: ID, DLC, cycle, and each signal's start
bit, length, byte order, sign, scale, offset, range, invalid value and float type. Every
difference carries our reason: the seed line, the reading recorded in ``specs/can/`` and the
decision it follows.

Messages are matched by frame ID, signals by name (case, ``_`` and spaces ignored) and, for a
name we do not have, by the bits they share with ours.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass
from functools import cache
from pathlib import Path
from typing import Any

from eyeq_spi.can.dbc import INVALID_ATTRIBUTE, database, require_cantools
from eyeq_spi.catalog.can import CanMessage, CanSignal, can_documents, protocol
from eyeq_spi.errors import InputError


@dataclass(frozen=True)
class Difference:
    id: int
    message: str
    signal: str | None
    field: str  # id | dlc | cycle | missing | extra | start | length | byte_order | ...
    ours: Any
    theirs: Any
    reason: str


def _norm(name: str) -> str:
    return re.sub(r"[^a-z0-9]", "", name.lower())


@cache
def _reasons(proto: str) -> dict[tuple[str, str | None], str]:
    """(message, signal or None) -> our recorded reading (description, reconstruction,
    differences) from the YAML of ``specs/can/``."""
    out: dict[tuple[str, str | None], str] = {}
    for doc in can_documents().values():
        p = doc.get("can_protocol") if isinstance(doc, dict) else None
        if not isinstance(p, dict) or p.get("name") != proto:
            continue
        for m in p["messages"]:
            parts = [str(m.get("reconstruction", ""))]
            parts += [str(d.get("text", "")) for d in m.get("differences") or []]
            out[(m["name"], None)] = " ".join(x for x in parts if x).strip()
            for s in m["signals"]:
                text = " ".join(str(s.get(k, "")) for k in ("description", "reconstruction")
                                if s.get(k))
                out[(m["name"], s["name"])] = text.strip()
    return out


def _why(proto: str, m: CanMessage, s: CanSignal | None) -> str:
    seed = (s.seed if s is not None else None) or m.seed or protocol(proto).seed
    line = s.seed_line if s is not None else m.seed_line
    own = _reasons(proto).get((m.name, s.name if s is not None else None), "")
    if s is not None and not own:
        own = _reasons(proto).get((m.name, None), "")
    where = f"seed {seed} line {line}"
    return f"{where}: {own}" if own else where


def _attr(sig: Any, name: str) -> Any:
    dbc = getattr(sig, "dbc", None)
    attr = dbc.attributes.get(name) if dbc is not None else None
    return None if attr is None else attr.value


def _bits(sig: Any) -> set[int]:
    if sig.byte_order == "little_endian":
        return set(range(sig.start, sig.start + sig.length))
    out, pos = set(), sig.start
    for _ in range(sig.length):
        out.add(pos)
        pos = pos - 1 if pos % 8 else pos + 15
    return out


def _close(a: float | None, b: float | None) -> bool:
    if a is None or b is None:
        return a is b
    return math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-12)


def _load(path: str) -> Any:
    cantools = require_cantools()
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{path}: no such file")
    try:
        return cantools.database.load_file(str(p), strict=False)
    except Exception as exc:  # cantools raises many kinds on a foreign or broken file
        raise InputError(f"{path}: not a readable DBC: {exc}") from exc


def compare(path: str, proto: str = "extlog2") -> list[Difference]:
    """Every difference between the DBC at ``path`` and ours, with our reasons."""
    theirs = _load(path)
    ours = database(proto)
    spec = protocol(proto)
    by_id = {m.frame_id: m for m in theirs.messages if not m.is_extended_frame}
    out: list[Difference] = []
    for m in spec.messages:
        for _, fid, name in m.instances():
            om = ours.get_message_by_frame_id(fid)
            tm = by_id.pop(fid, None)
            if tm is None:
                out.append(Difference(fid, name, None, "missing", name, None,
                                      _why(proto, m, None)))
                continue
            out += _message(proto, m, om, tm, fid, name)
    for fid, tm in sorted(by_id.items()):
        out.append(Difference(fid, tm.name, None, "extra", None, tm.name,
                              f"no message 0x{fid:X} in {spec.title}"))
    return out


def _message(proto: str, m: CanMessage, om: Any, tm: Any, fid: int,
             name: str) -> list[Difference]:
    out: list[Difference] = []
    why = _why(proto, m, None)
    if tm.length != om.length:
        out.append(Difference(fid, name, None, "dlc", om.length, tm.length, why))
    if tm.cycle_time is not None and tm.cycle_time != om.cycle_time:
        out.append(Difference(fid, name, None, "cycle", om.cycle_time, tm.cycle_time,
                              f"{why} (decision C3: the lower end of the printed range; C9: a "
                              "real camera's 75-81 ms is a deviation, not a different cycle)"))
    theirs = {_norm(s.name): s for s in tm.signals}
    matched: set[str] = set()
    for s in m.signals:
        os_ = om.get_signal_by_name(s.name)
        ts = theirs.get(_norm(s.name))
        if ts is None:
            out.append(Difference(fid, name, s.name, "missing", s.name, None,
                                  _why(proto, m, s)))
            continue
        matched.add(_norm(s.name))
        out += _signal(proto, m, s, os_, ts, fid, name)
        covered = sorted(o.name for o in m.signals if o.name != s.name
                         and _bits(om.get_signal_by_name(o.name)) & _bits(ts))
        if covered:  # their field runs over other signals of ours (a 13-bit Failsafe)
            lo, hi = min(_bits(ts)), max(_bits(ts))
            out.append(Difference(
                fid, name, s.name, "overlap", None,
                f"their {ts.name} (bits {lo}..{hi}) also covers our {', '.join(covered)}",
                "; ".join(_why(proto, m, m.signal(c)) for c in covered)))
    for key, ts in theirs.items():
        if key in matched:
            continue
        hit = sorted(s.name for s in m.signals
                     if _bits(om.get_signal_by_name(s.name)) & _bits(ts))
        lo, hi = min(_bits(ts)), max(_bits(ts))
        text = (f"their {ts.name} (bits {lo}..{hi}, {ts.length} bits) covers our "
                f"{', '.join(hit)}" if hit else f"their {ts.name} (bits {lo}..{hi}) is not "
                "a signal in our reading")
        reasons = "; ".join(_why(proto, m, m.signal(h)) for h in hit) or why
        out.append(Difference(fid, name, ts.name, "extra", None, text, reasons))
    return out


def _signal(proto: str, m: CanMessage, s: CanSignal, os_: Any, ts: Any, fid: int,
            name: str) -> list[Difference]:
    why = _why(proto, m, s)
    pairs: list[tuple[str, Any, Any, bool]] = [
        ("start", os_.start, ts.start, os_.start == ts.start),
        ("length", os_.length, ts.length, os_.length == ts.length),
        ("byte_order", os_.byte_order, ts.byte_order, os_.byte_order == ts.byte_order),
        ("signed", os_.is_signed, ts.is_signed, os_.is_signed == ts.is_signed),
        ("float", os_.is_float, ts.is_float, os_.is_float == ts.is_float),
        ("scale", os_.scale, ts.scale, _close(os_.scale, ts.scale)),
        ("offset", os_.offset, ts.offset, _close(os_.offset, ts.offset)),
    ]
    if ts.minimum is not None or ts.maximum is not None:
        pairs.append(("range", [os_.minimum, os_.maximum], [ts.minimum, ts.maximum],
                      _close(os_.minimum, ts.minimum) and _close(os_.maximum, ts.maximum)))
    their_invalid = _attr(ts, INVALID_ATTRIBUTE)
    if their_invalid is not None:
        mine = s.reported_invalid
        pairs.append(("invalid", mine, their_invalid, mine == their_invalid))
    out = []
    for field, a, b, same in pairs:
        if same:
            continue
        extra = ""
        if field == "scale" and b and a:
            extra = f" (theirs is {100.0 * (b - a) / a:+.1f}% off ours)"
        out.append(Difference(fid, name, s.name, field, a, b, why + extra))
    return out


def human(diffs: list[Difference], path: str, proto: str) -> str:
    if not diffs:
        return f"{path}: the same as our {proto} DBC (every message, signal and value)"
    lines = [f"{path} against our {proto} DBC: {len(diffs)} differences"]
    for d in diffs:
        where = f"0x{d.id:03X} {d.message}" + (f".{d.signal}" if d.signal else "")
        if d.field == "missing":
            what = "not in theirs"
        elif d.field in ("extra", "overlap"):
            what = f"only in theirs: {d.theirs}" if d.field == "extra" else str(d.theirs)
        else:
            what = f"{d.field}: ours {d.ours!r}, theirs {d.theirs!r}"
        lines.append(f"  {where}: {what}\n      our reason: {d.reason}")
    return "\n".join(lines)


def as_json(diffs: list[Difference]) -> list[dict[str, Any]]:
    return [asdict(d) for d in diffs]
