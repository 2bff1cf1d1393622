"""The message catalogue of ``specs/`` as typed, immutable objects.

Load once with :func:`catalog`; everything that builds a wire format (DASP/0x41/0x10 structs, MESP,
init bit tables) reads it from here, never from a layout written by hand (docs/STYLE.md §6).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from eyeq_spi.catalog.link import specs_dir
from eyeq_spi.catalog.schema import (  # normalise_sw: re-exported
    load_yaml_tree,
    normalise_sw,
    sw_key,
    validate_tree,
)
from eyeq_spi.errors import SpecError

SwKey = str
"""A variant key such as ``sw8_1``."""

sw_release = sw_key
"""``"sw8_1"`` -> ``(8, 1)``, ``"sw9"`` -> ``(9, 0)``: the numbers the EyeQ reports."""


def sw_release_text(key: SwKey) -> str:
    major, minor = sw_key(key)
    return f"{major}.{minor}"


def newest_at(keys: Iterable[SwKey], sw: SwKey) -> SwKey | None:
    """The newest variant key that is not newer than ``sw`` (decision D4), None if none."""
    return max((key for key in keys if sw_key(key) <= sw_key(sw)), key=sw_key, default=None)


@dataclass(frozen=True)
class Member:
    """One member of a struct in ``specs/structs/``: its name, type, count, enum and bits."""

    name: str
    type: str
    array: int | str | None = None
    bits: tuple[int, int] | None = None
    enum: str | None = None
    values: dict[int, str] | None = None
    units: str | None = None
    min: float | None = None
    max: float | None = None
    seed_line: int = 0
    description: str | None = None


@dataclass(frozen=True)
class Crc:
    """An E2E check of a struct (D5): its CRC member, its rolling counter and what it covers."""

    field: str
    counter: str | None
    covers: tuple[str, ...]


@dataclass(frozen=True)
class StructVariant:
    """A struct's members in one SW release range (seed 004 §7.1.4)."""

    key: SwKey
    seed_line: int
    members: tuple[Member, ...]
    crcs: tuple[Crc, ...] = ()


@dataclass(frozen=True)
class StructDef:
    """A struct of ``specs/structs/``, with its variants per SW release."""

    name: str
    section: str | None
    description: str | None
    variants: dict[SwKey, StructVariant]

    def variant_for(self, sw: SwKey) -> StructVariant | None:
        key = newest_at(self.variants, sw)
        return None if key is None else self.variants[key]


@dataclass(frozen=True)
class EnumValue:
    """One value of an enum: its number and name."""

    value: int
    name: str
    family: str | None = None
    semantic: str | None = None
    seed_line: int | None = None
    width: int = 1  # flags: bits of a multi-bit field starting at bit ``value``
    fields: dict[int, str] | None = None  # flags: names of a multi-bit field's values


@dataclass(frozen=True)
class EnumDef:
    """An enum of ``specs/enums/``: its values (or flags) and whether it is complete."""

    name: str
    kind: str  # "values" | "flags"
    values: dict[int, EnumValue]
    complete: bool = True  # False: the seed has values we could not read; others are no error

    def label(self, value: int) -> str | None:
        if self.kind == "flags":
            names = []
            for bit, flag in sorted(self.values.items()):
                part = value >> bit & ((1 << flag.width) - 1)
                if part and flag.width == 1:
                    names.append(flag.name)
                elif part:
                    names.append(f"{flag.name}={(flag.fields or {}).get(part, part)}")
            return "|".join(names) if names else None
        entry = self.values.get(value)
        return entry.name if entry else None


@dataclass(frozen=True)
class MessageDef:
    """An application message of ``specs/messages/``: protocol, data ID, direction, payload
    struct, rate and the SW releases that have it."""

    name: str
    data_id: int
    direction: str
    rate_hz: float | None
    tolerance_ms: tuple[float, float] | None
    modes: tuple[str, ...]
    since: SwKey
    until: SwKey | None
    payload: str
    section: str | None
    protocol: str  # "DASP" | "DIAG" | "BOOT"

    def exists_in(self, sw: SwKey) -> bool:
        if sw_key(sw) < sw_key(self.since):
            return False
        return self.until is None or sw_key(sw) <= sw_key(self.until)


@dataclass(frozen=True)
class InitSignal:
    """A signal of a CAN initialisation message."""

    name: str
    start: int
    length: int
    signed: bool
    factor: float
    offset: float
    min: float
    max: float
    initial: float
    units: str | None = None
    is_float: bool = False
    seed_line: int = 0


@dataclass(frozen=True)
class InitVariant:
    """An initialisation message's signals in one SW release range."""

    key: SwKey
    signals: tuple[InitSignal, ...]
    length_bytes: int


@dataclass(frozen=True)
class InitMessageDef:
    """A CAN initialisation message, with its variants per SW release."""

    name: str
    id: int
    ct_type: int | None
    rounding: str  # "round" (I1) or "truncate" (Appendix E, EEPROM)
    variants: dict[SwKey, InitVariant]

    def variant_for(self, sw: SwKey) -> InitVariant | None:
        key = newest_at(self.variants, sw)
        return None if key is None else self.variants[key]


@dataclass(frozen=True)
class MespParam:
    """A MESP request or reply parameter (M3): its name and type."""

    name: str
    type: str  # u8 | u16 | u32 | string | bytes


@dataclass(frozen=True)
class MespFunction:
    """A MESP function of ``specs/mesp.yaml``: service, function and parameters."""

    name: str
    service: int
    function: int
    request: tuple[MespParam, ...]
    reply: tuple[MespParam, ...]


@dataclass
class Catalog:
    """Everything ``specs/`` defines, validated; pickled by the start-up cache."""

    root: Path
    sw_versions: tuple[SwKey, ...]
    default_sw: SwKey
    constants: dict[str, dict[SwKey, int]]
    structs: dict[str, StructDef]
    enums: dict[str, EnumDef]
    messages: tuple[MessageDef, ...]
    init_messages: dict[str, InitMessageDef]
    mesp: tuple[MespFunction, ...]
    mesp_ret: dict[int, str] = field(default_factory=dict)
    raw: Mapping[str, Any] = field(default_factory=dict)  # RawDocs: file name -> parsed YAML

    def constant(self, name: str, sw: SwKey) -> int:
        table = self.constants.get(name)
        if table is None:
            raise SpecError(f"unknown constant {name}")
        key = newest_at(table, sw)
        if key is None:
            raise SpecError(f"constant {name} is not defined for {sw}")
        return table[key]

    def message(self, name: str) -> MessageDef:
        for msg in self.messages:
            if msg.name == name:
                return msg
        raise SpecError(f"unknown message {name}")

    def dasp_by_id(self, data_id: int, sw: SwKey) -> MessageDef | None:
        for msg in self.messages:
            if msg.protocol == "DASP" and msg.data_id == data_id and msg.exists_in(sw):
                return msg
        return None

    def sw(self, text: str | None) -> SwKey:
        key = normalise_sw(text, self.default_sw)
        if key not in self.sw_versions:
            known = ", ".join(sw_release_text(k) for k in self.sw_versions)
            raise SpecError(f"SW {text} is not a release in specs/ (known: {known})")
        return key


class RawDocs(Mapping[str, Any]):
    """The parsed YAML files of ``specs/`` by relative path. A file is read when first asked for
    (through the start-up cache, like ``spec_file``) and the pickled catalogue holds only the root:
    the raw documents were three quarters of its bytes and few starts need any."""

    def __init__(self, root: Path, docs: Mapping[str, Any] | None = None) -> None:
        self._root = root
        self._docs: dict[str, Any] = dict(docs or {})

    def __getitem__(self, name: str) -> Any:
        doc = self._docs.get(name)
        if doc is None:
            if name not in self._names():
                raise KeyError(name)
            from eyeq_spi.catalog.cache import cached_data
            from eyeq_spi.catalog.link import load_file

            path = self._root / name
            doc = self._docs[name] = cached_data(self._root, name, lambda: load_file(path))
        return doc

    def _names(self) -> list[str]:
        return sorted(str(p.relative_to(self._root)) for p in self._root.rglob("*.yaml"))

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())

    def __reduce__(self) -> tuple[Any, ...]:
        return (RawDocs, (self._root,))


def _member(raw: dict[str, Any]) -> Member:
    bits = raw.get("bits")
    values = raw.get("values")
    return Member(
        name=raw["name"],
        type=raw.get("type", "uint8"),
        array=raw.get("array"),
        bits=(int(bits[0]), int(bits[1])) if bits else None,
        enum=raw.get("enum"),
        values={int(k): str(v) for k, v in values.items()} if isinstance(values, dict) else None,
        units=raw.get("units"),
        min=raw.get("min"),
        max=raw.get("max"),
        seed_line=int(raw.get("seed_line", 0)),
        description=raw.get("description"),
    )


def _crcs(raw: Any) -> tuple[Crc, ...]:
    if raw is None:
        return ()
    items = raw if isinstance(raw, list) else [raw]
    return tuple(Crc(c["field"], c.get("counter"), tuple(c["covers"])) for c in items)


def _num(value: Any) -> float:
    """Keep ints exact (a 128-bit fuse ID does not survive a float); floats stay floats."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SpecError(f"not a number: {value!r}")
    return value


def _signal(raw: dict[str, Any]) -> InitSignal:
    return InitSignal(
        name=str(raw["name"]), start=int(raw["start"]), length=int(raw["length"]),
        signed=bool(raw.get("signed", False)), factor=_num(raw["factor"]),
        offset=_num(raw["offset"]), min=_num(raw["min"]), max=_num(raw["max"]),
        initial=_num(raw.get("initial", 0)), units=raw.get("units"),
        is_float=bool(raw.get("float", False)), seed_line=int(raw.get("seed_line", 0)),
    )


def load_catalog(root: Path) -> Catalog:
    docs = load_yaml_tree(root)
    problems = validate_tree(root, docs)
    if problems:
        raise SpecError(f"{root}: {len(problems)} schema problem(s), first: {problems[0]}")
    sw_doc = docs["sw_versions.yaml"]
    versions = tuple(v["key"] for v in sw_doc["sw_versions"])
    constants: dict[str, dict[SwKey, int]] = {}
    structs: dict[str, StructDef] = {}
    enums: dict[str, EnumDef] = {}
    messages: list[MessageDef] = []
    inits: dict[str, InitMessageDef] = {}
    mesp: list[MespFunction] = []
    mesp_ret: dict[int, str] = {}
    for doc in docs.values():
        for name, table in (doc.get("constants") or {}).items():
            constants[name] = {k: int(v) for k, v in table.items() if k.startswith("sw")}
        for name, struct in (doc.get("structs") or {}).items():
            variants = {
                str(k): StructVariant(
                    str(k), int(v["seed_line"]), tuple(_member(m) for m in v["members"]),
                    _crcs(v.get("crc")),
                )
                for k, v in struct["variants"].items()
            }
            structs[name] = StructDef(name, struct.get("section"), struct.get("description"),
                                      variants)
        for name, enum in (doc.get("enums") or {}).items():
            flags = enum.get("kind") == "flags"
            vals: dict[int, EnumValue] = {}
            for entry in enum["values"]:
                key = "bit" if flags else "value"
                lo, hi = entry["bits"] if flags and "bits" in entry else [entry[key], entry[key]]
                vals[int(lo)] = EnumValue(
                    int(lo), str(entry["name"]), entry.get("family"), entry.get("semantic"),
                    entry.get("seed_line"), int(hi) - int(lo) + 1,
                    ({int(k): str(n) for k, n in entry["values"].items()}
                     if "values" in entry else None),
                )
            enums[name] = EnumDef(name, "flags" if flags else "values", vals,
                                  bool(enum.get("complete", True)))
        for group, protocol in (("dasp", "DASP"), ("other", None)):
            for msg in doc.get(group) or []:
                proto = protocol or str(msg["protocol"])
                tol = msg.get("tolerance_ms")
                messages.append(MessageDef(
                    msg["name"], int(msg["data_id"]), msg.get("direction", "e2h"),
                    msg.get("rate_hz"), (float(tol[0]), float(tol[1])) if tol else None,
                    tuple(msg.get("modes") or ()),
                    msg.get("since") or versions[0], msg.get("until"), msg["payload"],
                    msg.get("section"), proto,
                ))
        for name, im in (doc.get("init_messages") or {}).items():
            variants_i: dict[SwKey, InitVariant] = {}
            for release, variant in (im.get("variants") or {}).items():
                signals = (_signal(s) for s in variant["signals"])
                sigs = tuple(sorted(signals, key=lambda s: s.start))
                nbytes = (variant.get("length_bytes")
                          or -(-max(s.start + s.length for s in sigs) // 8))
                variants_i[str(release)] = InitVariant(str(release), sigs, int(nbytes))
            inits[name] = InitMessageDef(
                name, int(im["id"]), im.get("ct_type"), im.get("rounding", "round"), variants_i
            )
        for function in doc.get("mesp_functions") or []:
            mesp.append(MespFunction(
                function["name"], int(function["service"]), int(function["function"]),
                tuple(MespParam(p["name"], p["type"]) for p in function.get("request") or []),
                tuple(MespParam(p["name"], p["type"]) for p in function.get("reply") or []),
            ))
        for code, ret in (doc.get("mesp_ret") or {}).items():
            mesp_ret[int(code)] = str(ret["name"] if isinstance(ret, dict) else ret)
    return Catalog(
        root, versions, sw_doc.get("default", versions[-1]), constants, structs, enums,
        tuple(messages), inits, tuple(mesp), mesp_ret, RawDocs(root, docs),
    )


@cache
def catalog() -> Catalog:
    """The catalogue of the shipped ``specs/``, from the start-up cache when it is current."""
    from eyeq_spi.catalog.cache import cached_catalog

    return cached_catalog(specs_dir(), load_catalog)
