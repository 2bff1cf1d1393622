"""``eyeq-spi can compare OTHER.dbc``: a user's (vendor's, public) DBC against the DBC built from
``specs/can/``, message by message and signal by signal: ID, DLC, cycle, and each signal's start
bit, length, byte order, sign, scale, offset, unit, range, invalid value, float type and
value table (choices). Each difference names what differs, ours -> theirs, and where our value
comes from (the seed line, the signal's own recorded reading, the decision); a difference that
is the same in every slot of a repeated message is one difference (``Obstacle_Data_B_0..12``).

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
from eyeq_spi.catalog.can import (
    CanMessage,
    CanSignal,
    can_documents,
    can_specs,
    protocol,
    signal_bits,
)
from eyeq_spi.errors import InputError


@dataclass(frozen=True)
class Difference:
    id: int
    message: str
    signal: str | None
    field: str  # dlc | cycle | missing | extra | overlap | start | length | unit | choices ...
    ours: Any
    theirs: Any
    reason: str
    ids: tuple[int, ...] = ()  # every frame ID the difference is in (the slots), id first


def _norm(name: str) -> str:
    return re.sub(r"[^a-z0-9]", "", name.lower())


@cache
def _reasons(proto: str) -> dict[tuple[str, str | None], str]:
    """(message, signal or None) -> our recorded reading (description, reconstruction,
    differences) from the YAML of ``specs/can/``."""
    out: dict[tuple[str, str | None], str] = {}
    for doc in can_documents().values():
        spec = doc.get("can_protocol") if isinstance(doc, dict) else None
        if not isinstance(spec, dict) or spec.get("name") != proto:
            continue
        for msg in spec["messages"]:
            parts = [str(msg.get("reconstruction", ""))]
            parts += [str(d.get("text", "")) for d in msg.get("differences") or []]
            out[(msg["name"], None)] = " ".join(x for x in parts if x).strip()
            for sig in msg["signals"]:
                text = " ".join(str(sig.get(k, "")) for k in ("description", "reconstruction")
                                if sig.get(k))
                out[(msg["name"], sig["name"])] = text.strip()
    return out


def _why(proto: str, msg: CanMessage, sig: CanSignal | None) -> str:
    seed = (sig.seed if sig is not None else None) or msg.seed or protocol(proto).seed
    line = sig.seed_line if sig is not None else msg.seed_line
    where = f"seed {seed} line {line}"
    if sig is None:
        return where
    own = _reasons(proto).get((msg.name, sig.name), "")  # the signal's own reading, never the
    return f"{where}: {own}" if own else where      # message's long notes


def _about(proto: str, msg: CanMessage, word: str) -> str:
    """The seed line of ``m`` and the sentences of its recorded reading that mention
    ``word`` (DLC): the reason for a message-level difference, not the whole reading."""
    text = _reasons(proto).get((msg.name, None), "")
    hits = [x.strip() for x in re.split(r"(?<=[.;])\s+", text) if word.lower() in x.lower()]
    return "; ".join([_why(proto, msg, None), *hits])


def _attr(sig: Any, name: str) -> Any:
    dbc = getattr(sig, "dbc", None)
    attr = dbc.attributes.get(name) if dbc is not None else None
    return None if attr is None else attr.value


def _bits(sig: Any) -> set[int]:
    return signal_bits(sig.start, sig.length, sig.byte_order)


def _close(left: float | None, right: float | None) -> bool:
    if left is None or right is None:
        return left is right
    return math.isclose(left, right, rel_tol=1e-6, abs_tol=1e-12)


def _load(path: str) -> Any:
    cantools = require_cantools()
    target = Path(path)
    if not target.is_file():
        raise InputError(f"{path}: no such file")
    try:
        return cantools.database.load_file(str(target), strict=False)
    except Exception as exc:  # cantools raises many kinds on a foreign or broken file
        raise InputError(f"{path}: not a readable DBC: {exc}") from exc


def compare(path: str, proto: str = "extlog2") -> list[Difference]:
    """Every difference between the DBC at ``path`` and ours, with our reasons."""
    theirs = _load(path)
    ours = database(proto)
    spec = protocol(proto)
    by_id = {msg.frame_id: msg for msg in theirs.messages if not msg.is_extended_frame}
    out: list[Difference] = []
    for msg in spec.messages:
        for _, fid, name in msg.instances():
            om = ours.get_message_by_frame_id(fid)
            tm = by_id.pop(fid, None)
            if tm is None:
                out.append(Difference(fid, name, None, "missing", name, None,
                                      _why(proto, msg, None)))
                continue
            out += _message(proto, msg, om, tm, fid, name)
    for fid, tm in sorted(by_id.items()):
        out.append(Difference(fid, tm.name, None, "extra", None, tm.name,
                              f"no message 0x{fid:X} in {spec.title}"))
    return out


def _message(proto: str, msg: CanMessage, om: Any, tm: Any, fid: int,
             name: str) -> list[Difference]:
    out: list[Difference] = []
    why = _why(proto, msg, None)
    if tm.length != om.length:
        out.append(Difference(fid, name, None, "dlc", om.length, tm.length,
                              _about(proto, msg, "DLC")))
    if tm.cycle_time is not None and tm.cycle_time != om.cycle_time:
        out.append(Difference(fid, name, None, "cycle", om.cycle_time, tm.cycle_time,
                              f"{why}; decision C3 (a printed range's lower end)"))
    theirs = {_norm(sig.name): sig for sig in tm.signals}
    matched: set[str] = set()
    for sig in msg.signals:
        os_ = om.get_signal_by_name(sig.name)
        ts = theirs.get(_norm(sig.name))
        if ts is None:
            out.append(Difference(fid, name, sig.name, "missing", sig.name, None,
                                  _why(proto, msg, sig)))
            continue
        matched.add(_norm(sig.name))
        out += _signal(proto, msg, sig, os_, ts, fid, name)
        covered = sorted(o.name for o in msg.signals if o.name != sig.name
                         and _bits(om.get_signal_by_name(o.name)) & _bits(ts))
        if covered:  # their field runs over other signals of ours (a 13-bit Failsafe)
            lo, hi = min(_bits(ts)), max(_bits(ts))
            out.append(Difference(
                fid, name, sig.name, "overlap", None,
                f"their {ts.name} (bits {lo}..{hi}) also covers our {', '.join(covered)}",
                "; ".join(_why(proto, msg, msg.signal(c)) for c in covered)))
    for key, ts in theirs.items():
        if key in matched:
            continue
        hit = sorted(sig.name for sig in msg.signals
                     if _bits(om.get_signal_by_name(sig.name)) & _bits(ts))
        lo, hi = min(_bits(ts)), max(_bits(ts))
        text = (f"their {ts.name} (bits {lo}..{hi}, {ts.length} bits) covers our "
                f"{', '.join(hit)}" if hit else f"their {ts.name} (bits {lo}..{hi}) is not "
                "a signal in our reading")
        reasons = "; ".join(_why(proto, msg, msg.signal(h)) for h in hit) or why
        out.append(Difference(fid, name, ts.name, "extra", None, text, reasons))
    return out


def _signal(proto: str, msg: CanMessage, sig: CanSignal, os_: Any, ts: Any, fid: int,
            name: str) -> list[Difference]:
    why = _why(proto, msg, sig)
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
    if ts.unit and (os_.unit or "") != ts.unit:
        pairs.append(("unit", os_.unit, ts.unit, False))
    if ts.choices:
        mine_c = {int(k): str(v) for k, v in (os_.choices or {}).items()}
        theirs_c = {int(k): str(v) for k, v in ts.choices.items()}
        if mine_c != theirs_c:
            keys = sorted(set(mine_c) | set(theirs_c))
            pairs.append(("choices", {k: mine_c.get(k) for k in keys
                                      if mine_c.get(k) != theirs_c.get(k)},
                          {k: theirs_c.get(k) for k in keys
                           if mine_c.get(k) != theirs_c.get(k)}, False))
    their_invalid = _attr(ts, INVALID_ATTRIBUTE)
    if their_invalid is not None:
        mine = sig.reported_invalid
        pairs.append(("invalid", mine, their_invalid, mine == their_invalid))
    out = []
    for field, ours, theirs, same in pairs:
        if same:
            continue
        extra = ""
        if field == "scale" and theirs and ours:
            extra = f" (theirs is {100.0 * (theirs - ours) / ours:+.1f}% off ours)"
        out.append(Difference(fid, name, sig.name, field, ours, theirs, why + extra))
    return out


def grouped(diffs: list[Difference], proto: str) -> list[Difference]:
    """The same difference in several slots of a repeated message as one (its ``ids`` lists
    them, its message reads ``Obstacle_Data_B_0..12``), in the order of their first slot."""
    base: dict[int, tuple[str, int, int]] = {}  # frame ID -> (definition, slot, slot count)
    for msg in protocol(proto).messages:
        for slot, fid, _ in msg.instances():
            base[fid] = (msg.name, slot if slot is not None else -1,
                         msg.slots.count if msg.slots else 0)
    groups: dict[tuple[Any, ...], list[Difference]] = {}
    for diff in diffs:
        mname, slot, _ = base.get(diff.id, (diff.message, -1, 0))
        key = (mname if slot >= 0 else diff.message, diff.signal, diff.field, repr(diff.ours),
               repr(diff.theirs))
        groups.setdefault(key, []).append(diff)
    out = []
    for (mname, *_), ds in groups.items():
        first = ds[0]
        if len(ds) == 1:
            out.append(Difference(**{**asdict(first), "ids": (first.id,)}))
            continue
        slots = [base[diff.id][1] for diff in ds]
        count = base[first.id][2]
        span = (f"{slots[0]}..{slots[-1]}" if slots == list(range(slots[0], slots[-1] + 1))
                else ",".join(map(str, slots)))
        label = f"{mname}_{span}" + ("" if len(slots) == count else f" ({len(slots)} of "
                                                                   f"{count} slots)")
        out.append(Difference(first.id, label, first.signal, first.field, first.ours,
                              first.theirs, first.reason.replace(first.message, mname),
                              tuple(diff.id for diff in ds)))
    return out


def detect(path: str) -> tuple[str | None, str]:
    """The protocol whose frame IDs a DBC holds most of, and how much of it (a hint when
    none)."""
    theirs = {m.frame_id for m in _load(path).messages if not m.is_extended_frame}
    best, text, score = None, "", 0.0
    for name, spec in sorted(can_specs()[0].items()):
        ids = {fid for m in spec.messages for _, fid, _ in m.instances()}
        share = len(ids & theirs) / len(ids)
        if share > score:
            best, score = name, share
            text = f"{len(ids & theirs)} of its {len(ids)} IDs"
    return best, text


def _value(field: str, value: Any) -> str:
    if field == "choices" and isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {v}" for k, v in value.items()) + "}"
    if isinstance(value, float):
        return f"{value:.10g}"
    return "-" if value is None else str(value)


def _what(diff: Difference) -> str:
    if diff.field == "missing":
        return "not in theirs"
    if diff.field == "extra":
        return f"only in theirs: {diff.theirs}"
    if diff.field == "overlap":
        return str(diff.theirs)
    name = {"dlc": "DLC", "start": "start bit", "signed": "sign", "byte_order": "byte order",
            "invalid": "invalid value"}.get(diff.field, diff.field)
    return f"{name} {_value(diff.field, diff.ours)} -> {_value(diff.field, diff.theirs)}"


def human(diffs: list[Difference], path: str, proto: str, detected: str = "") -> str:
    """One line per difference (``grouped`` ones), what differs ours -> theirs, then where
    ours comes from, folded to 80 columns."""
    import textwrap

    how = f" (detected: {detected})" if detected else ""
    if not diffs:
        return f"{path}: the same as our {proto} DBC{how} (every message, signal and value)"
    lines = [*textwrap.wrap(f"{path} against our {proto} DBC{how}: {len(diffs)} differences",
                            80, subsequent_indent="  "),
             "(each: what differs, ours -> theirs; then where ours comes from)"]
    entries: dict[tuple[str, str], list[str]] = {}  # one entry per signal and reason
    for diff in diffs:
        ids = (f"0x{diff.ids[0]:03X}..0x{diff.ids[-1]:03X}" if len(diff.ids) > 1
               else f"0x{diff.id:03X}")
        where = f"{ids} {diff.message}" + (f".{diff.signal}" if diff.signal else "")
        reason = diff.reason.split(" (theirs is ")[0] if diff.field == "scale" else diff.reason
        what = _what(diff) + (f" ({diff.reason.split(' (')[-1]}" if reason != diff.reason else "")
        entries.setdefault((where, reason), []).append(what)
    for (where, reason), whats in entries.items():
        lines += textwrap.wrap(f"{where}: {'; '.join(whats)}", 80, initial_indent="  ",
                               subsequent_indent="      ")
        lines += textwrap.wrap(f"ours: {reason}", 80, initial_indent="      ",
                               subsequent_indent="      ")
    return "\n".join(lines)


def as_json(diffs: list[Difference]) -> list[dict[str, Any]]:
    return [asdict(d) for d in diffs]
