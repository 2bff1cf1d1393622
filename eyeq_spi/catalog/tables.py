"""Tables of ``specs/`` that are not messages: the DASP header (§7.1.2), the GPIO definitions
(Appendix D), the Alignment NVM table (§21) and ``decisions.yaml``, as frozen typed objects
(:class:`~eyeq_spi.errors.SpecError` for a file that does not follow ``specs/SCHEMA.md``); and
:func:`validate_tables`, the schema checks of these files, of ``mesp.yaml`` and of every
``decision:`` reference in ``specs/``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from typing import Any

from eyeq_spi.catalog.link import spec_file
from eyeq_spi.errors import SpecError

DECISION_ID = re.compile(r"^[A-Z]\d+[a-z]?$")
"""A ``decision:`` value that names a decision (``D6``, ``L6a``); longer values are prose notes."""
MESP_TYPES = frozenset({"u8", "u16", "u32", "string", "bytes"})
MESP_PARAM_KEYS = frozenset({"name", "type", "seed_line", "decision", "reconstruction",
                             "description"})
GPIO_DIRECTIONS = frozenset({"eyeq_to_host", "host_to_eyeq"})
NVM_ACTIONS = frozenset({"update", "set_zero", "keep"})
UINT8_TYPES = frozenset({"uint8"})


# -- typed views ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Decision:
    """A normative decision of ``docs/PROTOCOL_DECISIONS.md`` (its id and title)."""

    id: str
    title: str
    section: str | None
    text: str


@dataclass(frozen=True)
class DaspHeaderField:
    """One field of the §7.1.2 DASP header: name, offset and size."""

    name: str
    offset: int
    value: int | None  # a constant byte (Protocol 0x65, RESERVED 0), else None
    seed_line: int


@dataclass(frozen=True)
class DaspHeader:
    """§7.1.2 / D1: ``Protocol, DataID, Counter, RESERVED`` then the DASP data."""

    size: int
    fields: tuple[DaspHeaderField, ...]
    reserved_data_ids: frozenset[int]
    counter_modulo: int
    unused_bits: int
    bad_sequence_counter: str
    bad_length_counter: str

    @property
    def protocol(self) -> int:
        value = next((entry.value for entry in self.fields if entry.name == "Protocol"), None)
        if value is None:
            raise SpecError("dasp_header.yaml: Protocol has no value")
        return value


@dataclass(frozen=True)
class GpioPin:
    """One pin of a GPIO group (its label and GPIO name)."""

    label: str
    gpio: str | None  # None where the OCR left it unreadable (see the reconstruction note)
    ball: str
    seed_line: int


@dataclass(frozen=True)
class GpioGroup:
    """A group of GPIO pins with one direction."""

    name: str
    direction: str  # eyeq_to_host | host_to_eyeq
    encoding: tuple[str, ...]  # pin labels, most significant bit first
    pins: tuple[GpioPin, ...]
    values: Mapping[int, str]

    def code(self, levels: Mapping[str, int]) -> int:
        """The group's value from the level (0/1) of each pin, keyed by schematic label."""
        out = 0
        for label in self.encoding:
            level = levels.get(label)
            if level not in (0, 1):
                raise SpecError(f"GPIO {self.name}: pin {label} needs level 0 or 1, not {level!r}")
            out = out << 1 | level
        return out

    def levels(self, code: int) -> dict[str, int]:
        """The pin levels that encode ``code`` (inverse of :meth:`code`)."""
        count = len(self.encoding)
        if not 0 <= code < 1 << count:
            raise SpecError(f"GPIO {self.name}: {code} does not fit {count} pin(s)")
        return {label: code >> (count - 1 - i) & 1 for i, label in enumerate(self.encoding)}


@dataclass(frozen=True)
class NvmParameter:
    """One parameter of an NVM table."""

    name: str
    type: str
    default: float
    source: str | None  # member of the calibration result, None when not measured
    init_signal: str  # Init_Params_Vision (0x92) signal the stored value is sent as
    init_factor: float = 1.0  # init value = stored value * init_factor
    value_on_update: float | None = None  # written on "update" when there is no source


@dataclass(frozen=True)
class NvmSource:
    """A source of NVM values (TAC, SPC, Autofix) and the mode it runs in."""

    name: str  # TAC | SPC | Autofix
    mode: str  # APP | SPC | TAC
    message: str
    result: str  # the struct holding the run's result
    run_mode: str | None  # dynamic_cal_run_mode value that names this source in 0xA2
    success: Mapping[str, str]  # member -> enum value name, all must hold
    actions: Mapping[str, str]  # parameter -> update | set_zero | keep


@dataclass(frozen=True)
class AlignmentNvm:
    """§21 Alignment NVM table."""

    parameters: tuple[NvmParameter, ...]
    sources: tuple[NvmSource, ...]

    def source(self, name: str) -> NvmSource:
        for source in self.sources:
            if source.name.lower() == name.lower():
                return source
        raise SpecError(f"§21 has no calibration source {name!r} "
                        f"(known: {', '.join(source.name for source in self.sources)})")

    def defaults(self) -> dict[str, float]:
        return {p.name: p.default for p in self.parameters}

    def apply(self, source: str, stored: Mapping[str, float],
              measured: Mapping[str, Any]) -> dict[str, float]:
        """The NVM after a *successful* run of ``source``: each cell of its row applied to
        ``stored`` with the run's ``measured`` result members."""
        row = self.source(source)
        out = {param.name: float(stored.get(param.name, param.default))
               for param in self.parameters}
        for param in self.parameters:
            action = row.actions[param.name]
            if action == "set_zero":
                out[param.name] = 0.0
            elif action == "update":
                if param.source is None:
                    on_update = param.value_on_update
                    out[param.name] = float(on_update if on_update is not None else 1)
                elif param.source not in measured:
                    raise SpecError(f"{row.name} result lacks {param.source} (for {param.name})")
                else:
                    out[param.name] = float(measured[param.source])
        return out

    def init_values(self, stored: Mapping[str, float]) -> dict[str, float]:
        """Init_Params_Vision signal values for the stored alignment."""
        return {p.init_signal: float(stored.get(p.name, p.default)) * p.init_factor
                for p in self.parameters}


# -- loaders -------------------------------------------------------------------------------------
def _checked(name: str, key: str) -> Any:
    doc = spec_file(name)
    problems = _CHECKS[name]({name: doc}, {})
    if problems:
        raise SpecError(f"specs/{name}: {len(problems)} problem(s), first: {problems[0]}")
    return doc[key]


@cache
def decisions() -> dict[str, Decision]:
    return {d["id"]: Decision(str(d["id"]), str(d["title"]), d.get("section"),
                              " ".join(str(d["text"]).split()))
            for d in _checked("decisions.yaml", "decisions")}


@cache
def dasp_header() -> DaspHeader:
    header = _checked("dasp_header.yaml", "dasp_header")
    return DaspHeader(
        int(header["size"]),
        tuple(DaspHeaderField(str(f["name"]), int(f["offset"]), f.get("value"),
                              int(f["seed_line"])) for f in header["fields"]),
        frozenset(int(x) for x in header.get("reserved_data_ids") or ()),
        int(header["counter"]["modulo"]), int(header["unused_bits"]),
        str(header["counter"]["diag_counter"]), str(header["bad_length"]["diag_counter"]),
    )


@cache
def gpio_groups() -> dict[str, GpioGroup]:
    return {
        g["name"]: GpioGroup(
            str(g["name"]), str(g["direction"]), tuple(g["encoding"]),
            tuple(GpioPin(str(p["label"]), p.get("gpio"), str(p["ball"]), int(p["seed_line"]))
                  for p in g["pins"]),
            {int(v["value"]): str(v["name"]) for v in g["values"]},
        )
        for g in _checked("gpio.yaml", "gpio")["groups"]
    }


@cache
def alignment_nvm() -> AlignmentNvm:
    """The §21 Alignment NVM table of ``specs/nvm.yaml`` (cross-checked against the catalogue
    by :func:`validate_tables` when the whole tree is validated)."""
    table = _checked("nvm.yaml", "alignment_nvm")
    params = tuple(
        NvmParameter(str(p["name"]), str(p["type"]), float(p["default"]), p.get("source"),
                     str(p["init_signal"]), float(p.get("init_factor", 1.0)),
                     p.get("value_on_update"))
        for p in table["parameters"]
    )
    sources = tuple(
        NvmSource(str(s["name"]), str(s["mode"]), str(s["message"]), str(s["result"]),
                  s.get("run_mode"), dict(s.get("success") or {}), dict(s["actions"]))
        for s in table["sources"]
    )
    return AlignmentNvm(params, sources)


# -- validation ----------------------------------------------------------------------------------
def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def flag_field_problems(entry: dict[str, Any], seen: set[int]) -> list[str]:
    """A multi-bit field of a ``kind: flags`` enum: ``{bits: [lo, hi], name, values: {0: ..}}``."""
    bits = entry.get("bits")
    if (not isinstance(bits, list) or len(bits) != 2 or not all(_is_int(bit) for bit in bits)
            or not 0 <= bits[0] <= bits[1] < 64):
        return [f"flag field {entry.get('name')!r}: bits must be [lo, hi] within 0..63"]
    problems = []
    if not isinstance(entry.get("name"), str) or not entry["name"]:
        problems.append(f"flag field bits {bits} without a name")
    values = entry.get("values")
    if values is not None and (not isinstance(values, dict) or not all(
            _is_int(k) and 0 <= k < 1 << (bits[1] - bits[0] + 1) and isinstance(n, str)
            for k, n in values.items())):
        problems.append(f"flag field {entry.get('name')}: values must map field values to names")
    for bit in range(bits[0], bits[1] + 1):
        if bit in seen:
            problems.append(f"flag field {entry.get('name')}: bit {bit} repeated")
        seen.add(bit)
    return problems


def _walk_decisions(node: Any, where: str, out: list[tuple[str, str]]) -> None:
    if isinstance(node, dict):
        decision = node.get("decision")
        if isinstance(decision, str) and DECISION_ID.match(decision):
            out.append((where, decision))
        for key, value in node.items():
            label = node.get("name", key) if key == "values" else key
            _walk_decisions(value, f"{where}/{label}", out)
    elif isinstance(node, list):
        for index, value in enumerate(node):
            label = value.get("name", value.get("id", index)) if isinstance(value, dict) else index
            _walk_decisions(value, f"{where}[{label}]", out)


def _check_decisions(docs: dict[str, Any], _ctx: dict[str, Any]) -> list[str]:
    problems: list[str] = []
    items = (docs.get("decisions.yaml") or {}).get("decisions")
    if not isinstance(items, list):
        return ["decisions.yaml: needs a 'decisions' list"]
    ids: set[str] = set()
    for item in items:
        if not isinstance(item, dict) or not isinstance(item.get("id"), str) \
                or not DECISION_ID.match(item["id"]):
            problems.append(f"decisions.yaml: entry without a decision id: {item!r}")
            continue
        if item["id"] in ids:
            problems.append(f"decisions.yaml: {item['id']} listed twice")
        ids.add(item["id"])
        for key in ("title", "text"):
            if not isinstance(item.get(key), str) or not item[key].strip():
                problems.append(f"decisions.yaml: {item['id']} needs a {key}")
    return problems


def _check_dasp_header(docs: dict[str, Any], _ctx: dict[str, Any]) -> list[str]:
    header = (docs.get("dasp_header.yaml") or {}).get("dasp_header")
    if not isinstance(header, dict):
        return ["dasp_header.yaml: needs a 'dasp_header' mapping"]
    problems = []
    size = header.get("size")
    fields = header.get("fields")
    if not isinstance(size, int) or not isinstance(fields, list):
        return ["dasp_header.yaml: needs an int size and a fields list"]
    offsets = []
    for entry in fields:
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str) \
                or not _is_int(entry.get("offset")) or not _is_int(entry.get("seed_line")):
            problems.append(f"dasp_header.yaml: field needs name, int offset, seed_line: {entry!r}")
            continue
        if entry.get("type") not in UINT8_TYPES:
            problems.append(f"dasp_header.yaml: {entry['name']}: header fields are uint8")
        if "value" in entry and not (_is_int(entry["value"]) and 0 <= entry["value"] <= 255):
            problems.append(f"dasp_header.yaml: {entry['name']}: value must be 0..255")
        offsets.append(entry["offset"])
    if sorted(offsets) != list(range(size)):
        problems.append(f"dasp_header.yaml: field offsets {offsets} do not cover 0..{size - 1}")
    names = {entry.get("name") for entry in fields if isinstance(entry, dict)}
    if "Protocol" not in names:
        problems.append("dasp_header.yaml: needs a Protocol field")
    for key, sub in (("counter", ("modulo", "diag_counter")), ("bad_length", ("diag_counter",))):
        if not isinstance(header.get(key), dict) or any(s not in header[key] for s in sub):
            problems.append(f"dasp_header.yaml: {key} needs {', '.join(sub)}")
    if not all(_is_int(x) for x in header.get("reserved_data_ids") or []):
        problems.append("dasp_header.yaml: reserved_data_ids must be ints")
    if header.get("unused_bits") not in (0, 1):
        problems.append("dasp_header.yaml: unused_bits must be 0 or 1")
    return problems


def _check_gpio(docs: dict[str, Any], _ctx: dict[str, Any]) -> list[str]:
    gpio = (docs.get("gpio.yaml") or {}).get("gpio")
    if not isinstance(gpio, dict) or not isinstance(gpio.get("groups"), list):
        return ["gpio.yaml: needs gpio.groups"]
    problems: list[str] = []
    names: set[str] = set()
    for grp in gpio["groups"]:
        where = f"gpio.yaml: group {grp.get('name') if isinstance(grp, dict) else grp!r}"
        if not isinstance(grp, dict) or not isinstance(grp.get("name"), str):
            problems.append(f"{where}: needs a name")
            continue
        if grp["name"] in names:
            problems.append(f"{where}: defined twice")
        names.add(grp["name"])
        if grp.get("direction") not in GPIO_DIRECTIONS:
            problems.append(f"{where}: direction must be one of {sorted(GPIO_DIRECTIONS)}")
        labels = set()
        for pin in grp.get("pins") or []:
            if not isinstance(pin, dict) or not isinstance(pin.get("label"), str) \
                    or not isinstance(pin.get("ball"), str) or not _is_int(pin.get("seed_line")):
                problems.append(f"{where}: pin needs label, ball and seed_line: {pin!r}")
                continue
            if pin.get("gpio") is None and not pin.get("reconstruction"):
                problems.append(f"{where}: pin {pin['label']} without gpio needs a reconstruction")
            labels.add(pin["label"])
        enc = grp.get("encoding")
        if not isinstance(enc, list) or not enc or not set(enc) <= labels:
            problems.append(f"{where}: encoding must list pins of the group")
            continue
        for value in grp.get("values") or []:
            if (not isinstance(value, dict) or not _is_int(value.get("value"))
                    or not isinstance(value.get("name"), str)
                    or not _is_int(value.get("seed_line"))):
                problems.append(f"{where}: value needs int value, name, seed_line: {value!r}")
            elif not 0 <= value["value"] < 1 << len(enc):
                problems.append(f"{where}: value {value['value']} does not fit {len(enc)} pin(s)")
    return problems


def _members(structs: dict[str, Any], name: str) -> dict[str, dict[str, Any]]:
    """Members of every variant of struct ``name`` (newest wins), by name."""
    out: dict[str, dict[str, Any]] = {}
    variants = (structs.get(name) or {}).get("variants") or {}
    for key in sorted(variants, key=lambda k: tuple(int(x) for x in k[2:].split("_"))):
        for member in variants[key].get("members") or []:
            if isinstance(member, dict) and "name" in member:
                out[member["name"]] = member
    return out


def _check_nvm(docs: dict[str, Any], ctx: dict[str, Any]) -> list[str]:
    table = (docs.get("nvm.yaml") or {}).get("alignment_nvm")
    if not isinstance(table, dict) or not isinstance(table.get("parameters"), list) \
            or not isinstance(table.get("sources"), list):
        return ["nvm.yaml: needs alignment_nvm.parameters and .sources"]
    problems: list[str] = []
    params: dict[str, dict[str, Any]] = {}
    for param in table["parameters"]:
        if not isinstance(param, dict) or not isinstance(param.get("name"), str):
            problems.append(f"nvm.yaml: parameter without a name: {param!r}")
            continue
        where = f"nvm.yaml: parameter {param['name']}"
        if param["name"] in params:
            problems.append(f"{where}: listed twice")
        params[param["name"]] = param
        if not isinstance(param.get("default"), (int, float)) or not isinstance(
                param.get("init_signal"), str) or not _is_int(param.get("seed_line")):
            problems.append(f"{where}: needs default, init_signal and seed_line")
        factor = param.get("init_factor", 1.0)
        if not isinstance(factor, (int, float)) or not math.isfinite(factor) or factor == 0:
            problems.append(f"{where}: init_factor must be a non-zero number")
        init = ctx.get("init_signals")
        if init is not None and param.get("init_signal") not in init:
            problems.append(f"{where}: {param.get('init_signal')!r} is no Init_Params_Vision "
                            "signal")
    for source in table["sources"]:
        if not isinstance(source, dict) or not isinstance(source.get("name"), str):
            problems.append(f"nvm.yaml: source without a name: {source!r}")
            continue
        where = f"nvm.yaml: source {source['name']}"
        actions = source.get("actions")
        if not isinstance(actions, dict) or set(actions) != set(params):
            problems.append(f"{where}: actions must name every parameter once")
        elif not set(actions.values()) <= NVM_ACTIONS:
            problems.append(f"{where}: actions must be among {sorted(NVM_ACTIONS)}")
        structs, enums = ctx.get("structs"), ctx.get("enums")
        if structs is None or enums is None:
            continue
        if source.get("message") not in ctx["messages"]:
            problems.append(f"{where}: unknown message {source.get('message')!r}")
        members = _members(structs, str(source.get("result")))
        if not members:
            problems.append(f"{where}: unknown result struct {source.get('result')!r}")
            continue
        for pname, param in params.items():
            if param.get("source") is not None and param["source"] not in members:
                problems.append(f"{where}: {source['result']} has no {param['source']} "
                                f"(for {pname})")
        checks = dict(source.get("success") or {})
        if source.get("run_mode") is not None:
            checks["runMode"] = source["run_mode"]
        for member, value in checks.items():
            enum = enums.get(str((members.get(member) or {}).get("enum")))
            names = {v.get("name") for v in (enum or {}).get("values") or []}
            if value not in names:
                problems.append(f"{where}: {member} = {value!r} is not a value of its enum")
    return problems


def _check_mesp(docs: dict[str, Any], _ctx: dict[str, Any]) -> list[str]:
    doc = docs.get("mesp.yaml")
    if not isinstance(doc, dict):
        return []
    problems = []
    for code, ret in (doc.get("mesp_ret") or {}).items():
        if not _is_int(code):
            problems.append(f"mesp.yaml: ret code {code!r} is not an int")
        if isinstance(ret, dict) and not (isinstance(ret.get("name"), str) and (
                "seed_line" in ret or "decision" in ret)):
            problems.append(f"mesp.yaml: ret {code} needs a name and a seed_line or decision")
        elif not isinstance(ret, (dict, str)):
            problems.append(f"mesp.yaml: ret {code} must be a name or a mapping")
    for function in doc.get("mesp_functions") or []:
        fname = function.get("name") if isinstance(function, dict) else function
        for side in ("request", "reply"):
            for param in (function.get(side) if isinstance(function, dict) else None) or []:
                label = param.get("name") if isinstance(param, dict) else param
                where = f"mesp.yaml: {fname} {side} {label}"
                if not isinstance(param, dict) or param.get("type") not in MESP_TYPES:
                    problems.append(f"{where}: type must be one of {sorted(MESP_TYPES)}")
                    continue
                for key in set(param) - MESP_PARAM_KEYS:
                    problems.append(f"{where}: unknown key {key!r}")
                if "seed_line" not in param and "decision" not in param:
                    problems.append(f"{where}: needs a seed_line or a decision")
    return problems


_CHECKS = {
    "decisions.yaml": _check_decisions,
    "dasp_header.yaml": _check_dasp_header,
    "gpio.yaml": _check_gpio,
    "nvm.yaml": _check_nvm,
    "mesp.yaml": _check_mesp,
}


def validate_tables(docs: dict[str, Any]) -> list[str]:
    """Schema problems of the files above, and ``decision:`` ids that decisions.yaml lacks.
    ``docs`` is the whole tree (relative path -> parsed YAML), as ``validate_tree`` loads it."""
    structs: dict[str, Any] = {}
    enums: dict[str, Any] = {}
    messages: set[str] = set()
    init_signals: set[str] = set()
    for doc in docs.values():
        if not isinstance(doc, dict):
            continue
        structs.update(doc.get("structs") or {})
        enums.update(doc.get("enums") or {})
        messages |= {str(m.get("name")) for m in doc.get("dasp") or [] if isinstance(m, dict)}
        vision = (doc.get("init_messages") or {}).get("Init_Params_Vision") or {}
        for var in (vision.get("variants") or {}).values():
            init_signals |= {s.get("name") for s in var.get("signals") or []}
    ctx = {"structs": structs, "enums": enums, "messages": messages,
           "init_signals": init_signals or None}
    problems: list[str] = []
    for name, check in _CHECKS.items():
        if name in docs:
            problems += check(docs, ctx)
    known = {d.get("id") for d in ((docs.get("decisions.yaml") or {}).get("decisions") or [])
             if isinstance(d, dict)}
    for rel, doc in docs.items():
        refs: list[tuple[str, str]] = []
        _walk_decisions(doc, rel, refs)
        problems += [f"{where}: decision {d} is not in decisions.yaml"
                     for where, d in refs if d not in known]
    return problems
