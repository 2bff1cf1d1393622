"""The Mobileye CAN output protocols of ``specs/can/`` (seeds 000, 001, 003) as typed objects,
and their schema check (``specs/SCHEMA.md`` "specs/can/").

One ``can_protocol`` document per protocol (``extlog2.yaml``, ``me8.yaml``) and one
``can_mapping`` document (``mapping.yaml``: EyeQ4 DASP fields -> CAN signals, decision C4).
Everything that builds a DBC, encodes a frame or decodes a log reads it from here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache
from typing import Any

from eyeq_spi.catalog.can_expr import compile_expr
from eyeq_spi.catalog.link import is_number, load_file, specs_dir
from eyeq_spi.errors import SpecError

PROTOCOL_KEYS = frozenset({"name", "title", "seeds", "bitrate", "seed", "seed_line", "enums",
                           "messages"})
MESSAGE_KEYS = frozenset({"name", "id", "dlc", "cycle_ms", "slots", "section", "seed",
                          "seed_line", "signals", "reconstruction", "differences", "description",
                          "quality"})
SIGNAL_KEYS = frozenset({"name", "start", "length", "byte_order", "signed", "scale", "offset",
                         "unit", "min", "max", "invalid", "invalid_means", "out_of_range", "enum",
                         "float", "seed", "seed_line", "seed_form", "description",
                         "reconstruction", "invented"})
SLOT_KEYS = frozenset({"count", "stride", "seed_line", "rule"})
QUALITY_KEYS = frozenset({"message", "signal", "valid_from", "governs", "seed_line", "decision"})
MAPPING_KEYS = frozenset({"expr", "reason", "seed_line"})
MESSAGE_MAPPING_KEYS = frozenset({"signals", "slots", "unmapped"})


@dataclass(frozen=True)
class CanSignal:
    name: str
    start: int
    length: int
    byte_order: str = "little_endian"
    signed: bool = False
    scale: float = 1.0
    offset: float = 0.0
    unit: str | None = None
    min: float | None = None
    max: float | None = None
    invalid: int | None = None  # raw bit pattern as printed (0x800), see raw_invalid
    # the normal state the printed invalid value also denotes (Failsafe 0 = No_Failsafe):
    # such a value is not reported invalid (decision C8)
    invalid_means: str | None = None
    out_of_range: str = "clamp"  # "clamp" | "invalid"
    enum: str | None = None
    is_float: bool = False
    seed_line: int = 0
    description: str | None = None
    seed: str | None = None  # the seed seed_line counts in, when not the message's

    @property
    def raw_invalid(self) -> int | None:
        """The invalid value as the raw integer a codec packs (two's complement if signed)."""
        if self.invalid is None:
            return None
        if self.signed and self.invalid >= 1 << (self.length - 1):
            return self.invalid - (1 << self.length)
        return self.invalid

    @property
    def reported_invalid(self) -> int | None:
        """The raw value a decoder reports as invalid: none when it is also a normal state."""
        return None if self.invalid_means is not None else self.raw_invalid

    def covered_bytes(self) -> int:
        """How many leading bytes of the payload hold this signal (decision C8 short DLC)."""
        return max(self.bits()) // 8 + 1

    def bits(self) -> set[int]:
        return signal_bits(self.start, self.length, self.byte_order)

    @property
    def raw_limits(self) -> tuple[int, int]:
        if self.signed:
            return -(1 << (self.length - 1)), (1 << (self.length - 1)) - 1
        return 0, (1 << self.length) - 1



def signal_bits(start: int, length: int, byte_order: str) -> set[int]:
    """Bit positions (bit 0 = LSB of byte 0, DBC numbering) a signal occupies."""
    if byte_order == "little_endian":
        return set(range(start, start + length))
    out, pos = set(), start  # Motorola: start is the MSB, walk towards the LSB
    for _ in range(length):
        out.add(pos)
        pos = pos - 1 if pos % 8 else pos + 15
    return out


@dataclass(frozen=True)
class SlotRule:
    count: int
    stride: int
    rule: str = ""


@dataclass(frozen=True)
class QualityRule:
    """Decision C11: the signals ``governs`` are valid only while ``signal`` (of ``message``,
    the same slot; this message when None) is at least ``valid_from``."""

    signal: str
    valid_from: int
    governs: tuple[str, ...]
    message: str | None = None
    seed_line: int = 0


@dataclass(frozen=True)
class CanMessage:
    name: str
    id: int
    dlc: int
    cycle_ms: float
    signals: tuple[CanSignal, ...]
    slots: SlotRule | None = None
    section: str | None = None
    seed_line: int = 0
    seed: str | None = None  # the seed seed_line counts in, when not the protocol's
    quality: QualityRule | None = None  # decision C11

    def instances(self) -> list[tuple[int | None, int, str]]:
        """(slot, frame ID, DBC message name): one per repeated slot, else one."""
        if self.slots is None:
            return [(None, self.id, self.name)]
        return [(i, self.id + i * self.slots.stride, f"{self.name}_{i}")
                for i in range(self.slots.count)]

    def signal(self, name: str) -> CanSignal:
        for sig in self.signals:
            if sig.name == name:
                return sig
        raise SpecError(f"{self.name} has no signal {name}")


@dataclass(frozen=True)
class CanProtocol:
    name: str
    title: str
    bitrate: int
    enums: dict[str, dict[int, str]]
    messages: tuple[CanMessage, ...]
    seeds: dict[str, str] = field(default_factory=dict)
    seed: str = ""  # the seed whose line numbers the messages give (extlog2: 001)

    def message(self, name: str) -> CanMessage:
        for msg in self.messages:
            if msg.name == name:
                return msg
        raise SpecError(f"protocol {self.name} has no message {name}")


@dataclass(frozen=True)
class SignalMapping:
    expr: str
    reason: str


@dataclass(frozen=True)
class MessageMapping:
    signals: dict[str, SignalMapping]
    slots: SignalMapping | None = None  # expression giving the list of slot items
    # signals with no EyeQ4 source (C4): name -> reason; sent as the invalid value, or
    # physical 0 clamped into range when the seed prints none
    unmapped: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class CanMapping:
    sources: dict[str, str]  # alias -> "DASP_MESSAGE_NAME[.path.to.struct]"
    tables: dict[str, dict[Any, int]]  # int -> int, plus an optional "default"
    protocols: dict[str, dict[str, MessageMapping]]
    derived: tuple[tuple[str, SignalMapping], ...] = ()


BASE_NAMES = frozenset({"t", "veh", "n", "i", "o"})
MAPPING_DOC_KEYS = frozenset({"vehicle", "sources", "tables", "derived", "protocols"})


def _table(raw: Any) -> dict[Any, int]:
    out: dict[Any, int] = {}
    for key, value in (raw or {}).items():
        if key == "identity":
            out.update({int(x): int(x) for x in value})
        elif key == "default":
            out["default"] = int(value)
        else:
            out[int(key)] = int(value)
    return out


def _check_signal(where: str, signal: Any, dlc: int, enums: dict[str, Any]) -> list[str]:
    if not isinstance(signal, dict):
        return [f"{where}: signal must be a mapping"]
    out = [f"{where}: unknown key {key!r}" for key in sorted(set(signal) - SIGNAL_KEYS)]
    if not isinstance(signal.get("name"), str) or not signal["name"].isidentifier():
        out.append(f"{where}: bad name {signal.get('name')!r}")
    if not isinstance(signal.get("start"), int) or not isinstance(signal.get("length"), int) \
            or not 1 <= signal["length"] <= 64 or signal["start"] < 0:
        return [*out, f"{where}: needs int start >= 0 and length 1..64"]
    if not isinstance(signal.get("seed_line"), int):
        out.append(f"{where}: needs an int seed_line")
    for key in ("scale", "offset", "min", "max"):
        if key in signal and not is_number(signal[key]):
            out.append(f"{where}: {key} must be a number")
    if signal.get("scale") == 0:
        out.append(f"{where}: scale 0")
    if signal.get("byte_order", "little_endian") not in ("little_endian", "big_endian"):
        out.append(f"{where}: byte_order must be little_endian or big_endian")
    if signal.get("out_of_range", "clamp") not in ("clamp", "invalid"):
        out.append(f"{where}: out_of_range must be clamp or invalid")
    if signal.get("out_of_range") == "invalid" and "invalid" not in signal:
        out.append(f"{where}: out_of_range invalid needs an invalid value")
    if "invalid" in signal and (not isinstance(signal["invalid"], int) or
                                not 0 <= signal["invalid"] < 1 << signal["length"]):
        out.append(f"{where}: invalid must be a raw value that fits {signal['length']} bits")
    if "invalid_means" in signal and (
            "invalid" not in signal or not isinstance(signal["invalid_means"], str)):
        out.append(f"{where}: invalid_means names the state an invalid value also means")
    if "enum" in signal and signal["enum"] not in enums:
        out.append(f"{where}: unknown enum {signal['enum']!r}")
    if signal.get("float") and signal["length"] != 32:
        out.append(f"{where}: a float signal is 32 bits")
    if (signal.get("invented") or "seed_form" in signal) and not signal.get("reconstruction"):
        out.append(f"{where}: invented/seed_form needs a reconstruction note")
    sig = _signal(signal)
    if max(sig.bits()) >= dlc * 8 or min(sig.bits()) < 0:
        out.append(f"{where}: bits {min(sig.bits())}..{max(sig.bits())} exceed DLC {dlc}")
    return out


def validate_protocol(rel: str, doc: Any) -> list[str]:
    if not isinstance(doc, dict):
        return [f"{rel}: can_protocol must be a mapping"]
    out = [f"{rel}: unknown key {k!r}" for k in sorted(set(doc) - PROTOCOL_KEYS)]
    if not isinstance(doc.get("name"), str):
        out.append(f"{rel}: needs a name")
    enums = doc.get("enums") or {}
    for ename, enum in enums.items():
        vals = enum.get("values") if isinstance(enum, dict) else None
        if not isinstance(vals, dict) or not all(isinstance(k, int) and isinstance(v, str)
                                                 for k, v in vals.items()):
            out.append(f"{rel}: enum {ename}: values must map ints to names")
    ids: dict[int, str] = {}
    names: set[str] = set()
    msgs = doc.get("messages")
    if not isinstance(msgs, list) or not msgs:
        return [*out, f"{rel}: needs a messages list"]
    for msg in msgs:
        where = f"{rel}: message {msg.get('name') if isinstance(msg, dict) else msg!r}"
        if not isinstance(msg, dict):
            out.append(f"{where}: must be a mapping")
            continue
        out += [f"{where}: unknown key {k!r}" for k in sorted(set(msg) - MESSAGE_KEYS)]
        if not isinstance(msg.get("id"), int) or not 0 <= msg["id"] <= 0x7FF:
            out.append(f"{where}: id must be an 11-bit int")
            continue
        if not isinstance(msg.get("dlc"), int) or not 1 <= msg["dlc"] <= 8:
            out.append(f"{where}: dlc must be 1..8")
            continue
        if not is_number(msg.get("cycle_ms")) or msg["cycle_ms"] <= 0:
            out.append(f"{where}: cycle_ms must be positive")
        if not isinstance(msg.get("seed_line"), int):
            out.append(f"{where}: needs an int seed_line")
        slots = msg.get("slots")
        if slots is not None and (not isinstance(slots, dict) or set(slots) - SLOT_KEYS
                                  or not isinstance(slots.get("count"), int)
                                  or not isinstance(slots.get("stride"), int)
                                  or slots["count"] < 1 or slots["stride"] < 1):
            out.append(f"{where}: slots needs int count and stride >= 1")
            continue
        count, stride = (slots["count"], slots["stride"]) if slots else (1, 1)
        for slot in range(count):
            fid = msg["id"] + slot * stride
            if fid in ids:
                out.append(f"{where}: ID 0x{fid:03X} also used by {ids[fid]}")
            ids[fid] = str(msg.get("name"))
        if msg.get("name") in names:
            out.append(f"{where}: duplicate name")
        names.add(str(msg.get("name")))
        used: dict[int, str] = {}
        snames: set[str] = set()
        for sig in msg.get("signals") or []:
            swhere = f"{where} signal {sig.get('name') if isinstance(sig, dict) else sig!r}"
            problems = _check_signal(swhere, sig, msg["dlc"], enums)
            out += problems
            if problems:
                continue
            if sig["name"] in snames:
                out.append(f"{swhere}: duplicate name")
            snames.add(sig["name"])
            for bit in _signal(sig).bits():
                if bit in used:
                    out.append(f"{swhere}: bit {bit} overlaps {used[bit]}")
                    break
                used[bit] = sig["name"]
        if not snames:
            out.append(f"{where}: needs signals")
        if msg.get("quality") is not None:
            by_name = {str(x.get("name")): x for x in msgs if isinstance(x, dict)}
            out += _check_quality(where, msg["quality"], msg, by_name)
    return out


def validate_mapping(rel: str, doc: Any, protocols: dict[str, Any]) -> list[str]:
    if not isinstance(doc, dict):
        return [f"{rel}: can_mapping must be a mapping"]
    out = [f"{rel}: unknown key {k!r}" for k in sorted(set(doc) - MAPPING_DOC_KEYS)]
    names = set(BASE_NAMES) | set(doc.get("sources") or {})
    tables = doc.get("tables") or {}
    for tname, table in tables.items():
        try:
            _table(table)
        except (TypeError, ValueError, AttributeError):
            out.append(f"{rel}: table {tname}: int -> int, identity: [ints], default: int")
    for dname, dm in (doc.get("derived") or {}).items():
        if not isinstance(dm, dict) or not isinstance(dm.get("reason"), str):
            out.append(f"{rel}: derived {dname}: needs expr and reason")
            continue
        try:
            compile_expr(str(dm.get("expr")), names, set(tables))
        except SpecError as exc:
            out.append(f"{rel}: derived {dname}: {exc}")
        names.add(str(dname))
    for pname, msgs in (doc.get("protocols") or {}).items():
        proto = protocols.get(pname)
        if proto is None:
            out.append(f"{rel}: unknown protocol {pname!r}")
            continue
        pmsgs = {m.get("name"): m for m in proto.get("messages") or [] if isinstance(m, dict)}
        for mname in sorted(set(pmsgs) - set(msgs or {}), key=str):
            out.append(f"{rel}: {pname}.{mname}: not mapped; map its signals or list them "
                       "under unmapped with a reason (C4)")
        for mname, mm in (msgs or {}).items():
            where = f"{rel}: {pname}.{mname}"
            if mname not in pmsgs:
                out.append(f"{where}: no such message")
                continue
            if not isinstance(mm, dict) or set(mm) - MESSAGE_MAPPING_KEYS:
                out.append(f"{where}: only signals, slots and unmapped")
                continue
            sig_names = {s.get("name") for s in pmsgs[mname].get("signals") or []}
            unmapped = mm.get("unmapped") or {}
            if not isinstance(unmapped, dict):
                out.append(f"{where}: unmapped is signal: reason")
                unmapped = {}
            for sname, why in unmapped.items():
                if sname not in sig_names:
                    out.append(f"{where}.{sname}: no such signal (unmapped)")
                if not isinstance(why, str) or not why.strip():
                    out.append(f"{where}.{sname}: an unmapped signal says why (C4)")
                if sname in (mm.get("signals") or {}):
                    out.append(f"{where}.{sname}: both mapped and unmapped")
            for sname in sorted(sig_names - set(mm.get("signals") or {}) - set(unmapped),
                                key=str):
                out.append(f"{where}.{sname}: neither mapped nor listed under unmapped (C4)")
            entries = dict((mm or {}).get("signals") or {})
            if "slots" in (mm or {}):
                entries["<slots>"] = mm["slots"]
            for sname, sm in entries.items():
                swhere = f"{where}.{sname}"
                if sname != "<slots>" and sname not in sig_names:
                    out.append(f"{swhere}: no such signal")
                if not isinstance(sm, dict) or set(sm) - MAPPING_KEYS:
                    out.append(f"{swhere}: needs expr and reason only")
                    continue
                if not isinstance(sm.get("reason"), str) or not sm["reason"].strip():
                    out.append(f"{swhere}: every mapping explains its choice (C4): add reason")
                try:
                    compile_expr(str(sm.get("expr")), names, set(tables))
                except SpecError as exc:
                    out.append(f"{swhere}: {exc}")
    return out


def validate_can_docs(docs: dict[str, Any]) -> list[str]:
    """Schema problems of every ``can_protocol`` / ``can_mapping`` document in ``docs``."""
    out: list[str] = []
    protocols: dict[str, Any] = {}
    for rel, doc in docs.items():
        if isinstance(doc, dict) and "can_protocol" in doc:
            out += validate_protocol(rel, doc["can_protocol"])
            if isinstance(doc["can_protocol"], dict):
                protocols[str(doc["can_protocol"].get("name"))] = doc["can_protocol"]
    for rel, doc in docs.items():
        if isinstance(doc, dict) and "can_mapping" in doc:
            out += validate_mapping(rel, doc["can_mapping"], protocols)
    return out


def _signal(raw: dict[str, Any]) -> CanSignal:
    return CanSignal(
        name=raw["name"], start=int(raw["start"]), length=int(raw["length"]),
        byte_order=raw.get("byte_order", "little_endian"), signed=bool(raw.get("signed", False)),
        scale=raw.get("scale", 1), offset=raw.get("offset", 0), unit=raw.get("unit"),
        min=raw.get("min"), max=raw.get("max"), invalid=raw.get("invalid"),
        invalid_means=raw.get("invalid_means"),
        out_of_range=raw.get("out_of_range", "clamp"), enum=raw.get("enum"),
        is_float=bool(raw.get("float", False)), seed_line=int(raw.get("seed_line", 0)),
        description=raw.get("description"),
        seed=str(raw["seed"]) if raw.get("seed") is not None else None,
    )


def _quality(raw: dict[str, Any]) -> QualityRule:
    return QualityRule(str(raw["signal"]), int(raw["valid_from"]), tuple(raw["governs"]),
                       str(raw["message"]) if raw.get("message") else None,
                       int(raw.get("seed_line", 0)))


def _check_quality(where: str, rule: Any, message: dict[str, Any],
                   by_name: dict[str, dict[str, Any]]) -> list[str]:
    """A C11 rule names a signal of its own (or of ``message``, slotted alike) and signals of
    its own message."""
    if not isinstance(rule, dict) or set(rule) - QUALITY_KEYS or not isinstance(
            rule.get("valid_from"), int) or not isinstance(rule.get("governs"), list):
        return [f"{where}: quality needs signal, valid_from (int) and governs (a list)"]
    src = by_name.get(str(rule["message"])) if rule.get("message") else message
    if src is None:
        return [f"{where}: quality: no message {rule['message']!r}"]
    if (src.get("slots") or {}).get("count") != (message.get("slots") or {}).get("count"):
        return [f"{where}: quality: {src['name']} has other slots"]
    out = []
    if rule.get("signal") not in {s.get("name") for s in src.get("signals") or []}:
        out.append(f"{where}: quality: {src['name']} has no signal {rule.get('signal')!r}")
    own = {s.get("name") for s in message.get("signals") or []}
    out += [f"{where}: quality governs {g!r}, not a signal of it" for g in rule["governs"]
            if g not in own]
    return out


def _protocol(doc: dict[str, Any]) -> CanProtocol:
    msgs = []
    for msg in doc["messages"]:
        sl = msg.get("slots")
        msgs.append(CanMessage(
            name=msg["name"], id=int(msg["id"]), dlc=int(msg["dlc"]), cycle_ms=msg["cycle_ms"],
            signals=tuple(_signal(s) for s in msg["signals"]),
            slots=SlotRule(int(sl["count"]), int(sl["stride"]), str(sl.get("rule", "")))
            if sl else None, section=msg.get("section"), seed_line=int(msg["seed_line"]),
            seed=str(msg["seed"]) if msg.get("seed") is not None else None,
            quality=_quality(msg["quality"]) if msg.get("quality") else None,
        ))
    enums = {k: {int(v): str(n) for v, n in e["values"].items()}
             for k, e in (doc.get("enums") or {}).items()}
    return CanProtocol(doc["name"], str(doc.get("title", doc["name"])),
                       int(doc.get("bitrate", 500000)), enums, tuple(msgs),
                       dict(doc.get("seeds") or {}), str(doc.get("seed", "")))


@cache
def can_documents() -> dict[str, Any]:
    """The YAML documents of ``specs/can/`` as loaded (with their notes: ``reconstruction``,
    ``differences``, ``description``), for tools that explain a reading."""
    return {f"can/{path.name}": load_file(path)
            for path in sorted((specs_dir() / "can").glob("*.yaml"))}


@cache
def can_specs() -> tuple[dict[str, CanProtocol], CanMapping]:
    """Every protocol of ``specs/can/`` and the DASP -> CAN mapping, validated."""
    docs = can_documents()
    problems = validate_can_docs(docs)
    if problems:
        raise SpecError(f"specs/can: {len(problems)} schema problem(s), first: {problems[0]}")
    protocols = {p.name: p for p in (_protocol(doc["can_protocol"]) for doc in docs.values()
                                     if isinstance(doc, dict) and "can_protocol" in doc)}
    mapping = CanMapping({}, {}, {})
    for doc in docs.values():
        if isinstance(doc, dict) and "can_mapping" in doc:
            mp = doc["can_mapping"]
            prot: dict[str, dict[str, MessageMapping]] = {}
            for pname, msgs in (mp.get("protocols") or {}).items():
                prot[pname] = {}
                for mname, mm in (msgs or {}).items():
                    sl = mm.get("slots")
                    prot[pname][mname] = MessageMapping(
                        {k: SignalMapping(str(v["expr"]), str(v["reason"]))
                         for k, v in (mm.get("signals") or {}).items()},
                        SignalMapping(str(sl["expr"]), str(sl["reason"])) if sl else None,
                        {str(k): str(v) for k, v in (mm.get("unmapped") or {}).items()})
            mapping = CanMapping(
                dict(mp.get("sources") or {}),
                {k: _table(v) for k, v in (mp.get("tables") or {}).items()},
                prot,
                tuple((str(k), SignalMapping(str(v["expr"]), str(v["reason"])))
                      for k, v in (mp.get("derived") or {}).items()))
    return protocols, mapping


def protocol(name: str) -> CanProtocol:
    protocols, _ = can_specs()
    if name not in protocols:
        raise SpecError(f"unknown CAN protocol {name!r}: choose {', '.join(sorted(protocols))}")
    return protocols[name]
