"""Validation of the ``specs/`` tree against the schema in ``specs/SCHEMA.md``.

The validator returns a list of human-readable problems instead of raising, so that a test (or
``python -m eyeq_spi.catalog.schema specs/``) can print all of them at once.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Any

from eyeq_spi.catalog.link import is_number, load_file
from eyeq_spi.errors import SpecError

PRIMITIVES = frozenset(
    ["uint8", "uint16", "uint32", "uint64", "int8", "int16", "int32", "int64", "real32", "real64",
     "bool"]
)
BITFIELD_CONTAINERS = frozenset(["uint8", "uint16", "uint32", "uint64", "int8", "int16", "int32"])
CONTAINER_BITS = {"uint8": 8, "int8": 8, "uint16": 16, "int16": 16, "uint32": 32,
                  "int32": 32, "uint64": 64}
VARIANT_RE = re.compile(r"^sw\d+(_\d+)?$")
NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
MODES = frozenset({"APP", "SPC", "TAC", "DIAG"})

MEMBER_KEYS = frozenset(
    {"name", "type", "array", "bits", "enum", "values", "units", "min", "max", "seed_line",
     "seed_form", "invented", "reconstruction", "description", "decision"}
)
VARIANT_KEYS = frozenset({"seed_line", "members", "crc", "reconstruction", "description",
                          "decision"})
STRUCT_KEYS = frozenset({"section", "description", "variants", "reconstruction", "decision"})
SIGNAL_KEYS = frozenset(
    {"name", "start", "length", "signed", "factor", "offset", "min", "max", "initial", "units",
     "seed_line", "reconstruction", "description", "float", "enum", "values", "seed_form"}
)


def sw_key(variant: str) -> tuple[int, int]:
    """``sw8_1`` -> (8, 1); used to order variants."""
    major, _, minor = variant[2:].partition("_")
    return int(major), int(minor or 0)


_SW_INPUT = re.compile(r"^(?:sw)?(\d+)(?:[._](\d+))?$", re.IGNORECASE)


def normalise_sw(text: str | None, default: str) -> str:
    """``"8.1"``, ``"SW8.1"``, ``"sw8_1"`` -> ``"sw8_1"``; ``"9"``/``"9.0"`` -> ``"sw9"``."""
    if text is None:
        return default
    match = _SW_INPUT.match(text.strip())
    if not match:
        raise SpecError(f"not a SW version: {text!r} (try 9.0, 8.1 or sw8_1)")
    major, minor = int(match.group(1)), int(match.group(2) or 0)
    return f"sw{major}" if minor == 0 else f"sw{major}_{minor}"


def load_yaml_tree(root: Path) -> dict[str, Any]:
    """Load every YAML file of ``root`` into one dict keyed by relative path."""
    return {str(path.relative_to(root)): load_file(path) for path in sorted(root.rglob("*.yaml"))}


def validate_tree(root: Path, docs: dict[str, Any] | None = None) -> list[str]:
    """Every schema problem of ``root`` (``docs``: the tree already loaded, to parse it once)."""
    if docs is None:
        docs = load_yaml_tree(root)
    problems: list[str] = []
    constants, structs, enums = _index(docs, problems)
    problems += _constant_problems(constants)
    problems += _enum_problems(enums)
    for sname, (rel, struct) in structs.items():
        problems += _struct_problems(f"{rel}: struct {sname}", struct, structs, constants, enums)
    for rel, doc in docs.items():
        if not isinstance(doc, dict):
            continue
        for msg in doc.get("dasp") or []:
            problems += _dasp_problems(rel, msg, structs)
        for msg in doc.get("other") or []:
            if not isinstance(msg, dict) or msg.get("protocol") not in ("DIAG", "BOOT"):
                problems.append(f"{rel}: message {msg!r}: protocol must be DIAG or BOOT")
        for iname, init in (doc.get("init_messages") or {}).items():
            problems += _init_message_problems(f"{rel}: init message {iname}", init)
    from eyeq_spi.catalog.tables import validate_tables  # GPIO, NVM, DASP header, decisions, MESP

    problems += validate_tables(docs)
    from eyeq_spi.catalog.can import validate_can_docs  # specs/can/ (seeds 000, 001, 003)

    problems += validate_can_docs(docs)
    return problems


_Structs = dict[str, tuple[str, dict[str, Any]]]


def _index(docs: dict[str, Any], problems: list[str]
           ) -> tuple[dict[str, Any], _Structs, dict[str, Any]]:
    """The constants, structs (with the file naming each) and enums of the whole tree."""
    constants: dict[str, Any] = {}
    structs: _Structs = {}
    enums: dict[str, Any] = {}
    for rel, doc in docs.items():
        if not isinstance(doc, dict):
            problems.append(f"{rel}: top level must be a mapping")
            continue
        if "constants" in doc:
            constants.update(doc["constants"] or {})
        for name, struct in (doc.get("structs") or {}).items():
            if name in structs:
                problems.append(f"{rel}: struct {name} also defined in {structs[name][0]}")
            structs[name] = (rel, struct)
        for name, enum in (doc.get("enums") or {}).items():
            if name in enums:
                problems.append(f"{rel}: enum {name} defined twice")
            enums[name] = enum
    return constants, structs, enums


def _constant_problems(constants: dict[str, Any]) -> list[str]:
    problems: list[str] = []
    for cname, cval in constants.items():
        if not isinstance(cval, dict) or not any(VARIANT_RE.match(key) for key in cval):
            problems.append(f"constant {cname}: must map variant keys to ints")
            continue
        for key, value in cval.items():
            if key in ("seed_line", "reconstruction"):
                continue
            if not VARIANT_RE.match(key) or not isinstance(value, int):
                problems.append(f"constant {cname}: bad entry {key}: {value!r}")
    return problems


def _enum_problems(enums: dict[str, Any]) -> list[str]:
    problems: list[str] = []
    for ename, enum in enums.items():
        where = f"enum {ename}"
        if not isinstance(enum, dict) or not isinstance(enum.get("values"), list):
            problems.append(f"{where}: needs a 'values' list")
            continue
        flags = enum.get("kind") == "flags"
        if "complete" in enum and not isinstance(enum["complete"], bool):
            problems.append(f"{where}: complete must be true or false")
        seen: set[int] = set()
        key = "bit" if flags else "value"
        for entry in enum["values"]:
            if flags and isinstance(entry, dict) and "bits" in entry:  # a multi-bit field
                from eyeq_spi.catalog.tables import flag_field_problems

                problems += [f"{where}: {p}" for p in flag_field_problems(entry, seen)]
                continue
            if not isinstance(entry, dict) or not isinstance(entry.get(key), int):
                problems.append(f"{where}: entry without int {key}: {entry!r}")
                continue
            if not isinstance(entry.get("name"), str) or not entry["name"]:
                problems.append(f"{where}: entry {entry[key]} without a name")
            if entry[key] in seen:
                problems.append(f"{where}: {key} {entry[key]} repeated")
            seen.add(entry[key])
    return problems


def _struct_problems(where: str, struct: Any, structs: _Structs, constants: dict[str, Any],
                     enums: dict[str, Any]) -> list[str]:
    if not isinstance(struct, dict):
        return [f"{where}: must be a mapping"]
    problems = [f"{where}: unknown key {key!r}" for key in set(struct) - STRUCT_KEYS]
    variants = struct.get("variants")
    if not isinstance(variants, dict) or not variants:
        return [*problems, f"{where}: needs variants"]
    for vname, var in variants.items():
        vwhere = f"{where} variant {vname}"
        if not VARIANT_RE.match(str(vname)):
            problems.append(f"{vwhere}: variant key must look like sw5 or sw8_1")
        if not isinstance(var, dict):
            problems.append(f"{vwhere}: must be a mapping")
            continue
        problems += [f"{vwhere}: unknown key {key!r}" for key in set(var) - VARIANT_KEYS]
        if not isinstance(var.get("seed_line"), int):
            problems.append(f"{vwhere}: needs an int seed_line")
        members = var.get("members")
        if not isinstance(members, list) or not members:
            problems.append(f"{vwhere}: needs a non-empty members list")
            continue
        names: set[str] = set()
        for member in members:
            problems += _member_problems(vwhere, member, names, structs, constants, enums)
        crcs = var.get("crc")
        if crcs is not None:
            for crc in crcs if isinstance(crcs, list) else [crcs]:
                problems += _crc_problems(vwhere, crc, names)
    return problems


def _member_problems(vwhere: str, member: Any, names: set[str], structs: _Structs,
                     constants: dict[str, Any], enums: dict[str, Any]) -> list[str]:
    """The problems of one struct member; its name is added to ``names``."""
    if not isinstance(member, dict):
        return [f"{vwhere}: member {member!r} is not a mapping"]
    mname = member.get("name")
    mwhere = f"{vwhere} member {mname}"
    if not isinstance(mname, str) or not NAME_RE.match(mname):
        return [f"{mwhere}: bad name"]
    problems = [f"{mwhere}: duplicate name"] if mname in names else []
    names.add(mname)
    problems += [f"{mwhere}: unknown key {key!r}" for key in set(member) - MEMBER_KEYS]
    mtype = member.get("type", "uint8" if "bits" in member else None)
    if mtype not in PRIMITIVES and mtype not in structs:
        problems.append(f"{mwhere}: unknown type {mtype!r}")
    if not isinstance(member.get("seed_line"), int):
        problems.append(f"{mwhere}: needs an int seed_line")
    array = member.get("array")
    if array is not None and not ((isinstance(array, int) and array > 0) or array in constants):
        problems.append(f"{mwhere}: array {array!r} is neither int nor constant")
    if "enum" in member and member["enum"] not in enums:
        problems.append(f"{mwhere}: unknown enum {member['enum']!r}")
    for key in ("min", "max"):
        if key in member and member[key] is not None and not is_number(member[key]):
            problems.append(f"{mwhere}: {key} must be a number")
    bits = member.get("bits")
    if bits is None:
        return problems
    if (not isinstance(bits, list) or len(bits) != 2
            or not all(isinstance(bit, int) for bit in bits) or bits[0] > bits[1]):
        return [*problems, f"{mwhere}: bits must be [lo, hi]"]
    if mtype not in BITFIELD_CONTAINERS:
        problems.append(f"{mwhere}: bitfield container {mtype!r}")
    elif bits[1] >= CONTAINER_BITS[mtype]:
        problems.append(f"{mwhere}: bits {bits} exceed {mtype}")
    if array is not None:
        problems.append(f"{mwhere}: bitfield arrays are not supported")
    return problems


def _crc_problems(vwhere: str, crc: Any, names: set[str]) -> list[str]:
    if not isinstance(crc, dict):
        return [f"{vwhere}: crc must be a mapping or a list of mappings"]
    problems: list[str] = []
    if crc.get("field") not in names:
        problems.append(f"{vwhere}: crc field {crc.get('field')!r} not a member")
    if crc.get("counter") is not None and crc.get("counter") not in names:
        problems.append(f"{vwhere}: crc counter {crc.get('counter')!r} not a member")
    covers = crc.get("covers")
    if not isinstance(covers, list) or not covers:
        return [*problems, f"{vwhere}: crc needs a covers list"]
    return problems + [f"{vwhere}: crc covers unknown signal {signal!r}" for signal in covers
                       if not isinstance(signal, str)
                       or signal.split(".")[0].split("[")[0] not in names]


def _dasp_problems(rel: str, msg: Any, structs: _Structs) -> list[str]:
    where = f"{rel}: message {msg.get('name') if isinstance(msg, dict) else msg!r}"
    if not isinstance(msg, dict):
        return [f"{where}: must be a mapping"]
    problems: list[str] = []
    if not isinstance(msg.get("data_id"), int) or not 0 <= msg["data_id"] <= 255:
        problems.append(f"{where}: data_id must be 0..255")
    elif msg["data_id"] == 0x5E:
        problems.append(f"{where}: data_id 0x5E is reserved for MESP (7.1.2)")
    if msg.get("direction") not in ("h2e", "e2h"):
        problems.append(f"{where}: direction must be h2e or e2h")
    if msg.get("payload") not in structs:
        problems.append(f"{where}: payload {msg.get('payload')!r} is not a struct")
    if not set(msg.get("modes") or []) <= MODES:
        problems.append(f"{where}: modes must be among {sorted(MODES)}")
    if not is_number(msg.get("rate_hz")):
        problems.append(f"{where}: rate_hz must be a number")
    return problems


def _init_message_problems(where: str, init: Any) -> list[str]:
    if not isinstance(init, dict) or not isinstance(init.get("id"), int):
        return [f"{where}: needs an int id"]
    problems: list[str] = []
    for vname, var in (init.get("variants") or {}).items():
        vwhere = f"{where} variant {vname}"
        if not VARIANT_RE.match(str(vname)):
            problems.append(f"{vwhere}: bad variant key")
        signals = var.get("signals") if isinstance(var, dict) else None
        if not isinstance(signals, list) or not signals:
            problems.append(f"{vwhere}: needs signals")
            continue
        used: dict[int, str] = {}
        snames: set[str | None] = set()
        for sig in signals:
            problems += _signal_problems(f"{vwhere} signal {sig.get('name')}", sig, used, snames)
    return problems


def _signal_problems(swhere: str, sig: dict[str, Any], used: dict[int, str],
                     snames: set[str | None]) -> list[str]:
    """The problems of one init-message signal; its bits go into ``used``, its name into
    ``snames``."""
    problems = [f"{swhere}: unknown key {key!r}" for key in set(sig) - SIGNAL_KEYS]
    if sig.get("name") in snames:
        problems.append(f"{swhere}: duplicate name")
    snames.add(sig.get("name"))
    if not isinstance(sig.get("start"), int) or not isinstance(
        sig.get("length"), int
    ) or sig["length"] < 1:
        return [*problems, f"{swhere}: needs int start and length"]
    for key in ("factor", "offset", "min", "max"):
        if not is_number(sig.get(key)):
            problems.append(f"{swhere}: {key} must be a number")
    if is_number(sig.get("factor")) and sig["factor"] == 0:
        problems.append(f"{swhere}: factor 0")
    for bit in range(sig["start"], sig["start"] + sig["length"]):
        if bit in used:
            problems.append(f"{swhere}: bit {bit} overlaps {used[bit]}")
            break
        used[bit] = sig["name"]
    return problems


def main(argv: list[str]) -> int:
    root = Path(argv[1] if len(argv) > 1 else "specs")
    problems = validate_tree(root)
    for problem in problems:
        print(problem)
    print(f"{len(problems)} problem(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
