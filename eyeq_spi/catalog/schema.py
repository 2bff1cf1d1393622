"""Validation of the ``specs/`` tree against the schema in ``specs/SCHEMA.md``.

The validator returns a list of human-readable problems instead of raising, so that a test (or
``python -m eyeq_spi.catalog.schema specs/``) can print all of them at once.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Any

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


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


_SW_INPUT = re.compile(r"^(?:sw)?(\d+)(?:[._](\d+))?$", re.IGNORECASE)


def normalise_sw(text: str | None, default: str) -> str:
    """``"8.1"``, ``"SW8.1"``, ``"sw8_1"`` -> ``"sw8_1"``; ``"9"``/``"9.0"`` -> ``"sw9"``."""
    if text is None:
        return default
    m = _SW_INPUT.match(text.strip())
    if not m:
        raise SpecError(f"not a SW version: {text!r} (try 9.0, 8.1 or sw8_1)")
    major, minor = int(m.group(1)), int(m.group(2) or 0)
    return f"sw{major}" if minor == 0 else f"sw{major}_{minor}"


def safe_loader() -> Any:
    """libyaml's loader, about 8x faster than the pure-Python one on specs/; same safe subset.
    yaml is imported here, not at module level: a start from the catalogue cache never needs
    it."""
    import yaml

    return getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def load_yaml_tree(root: Path) -> dict[str, Any]:
    """Load every YAML file of ``root`` into one dict keyed by relative path."""
    import yaml

    loader = safe_loader()
    out: dict[str, Any] = {}
    for path in sorted(root.rglob("*.yaml")):
        with path.open(encoding="utf-8") as fh:
            out[str(path.relative_to(root))] = yaml.load(fh, Loader=loader)
    return out


def validate_tree(root: Path, docs: dict[str, Any] | None = None) -> list[str]:
    """Every schema problem of ``root`` (``docs``: the tree already loaded, to parse it once)."""
    problems: list[str] = []
    if docs is None:
        docs = load_yaml_tree(root)
    constants: dict[str, Any] = {}
    structs: dict[str, tuple[str, dict[str, Any]]] = {}
    enums: dict[str, Any] = {}

    for rel, doc in docs.items():
        if not isinstance(doc, dict):
            problems.append(f"{rel}: top level must be a mapping")
            continue
        if "constants" in doc:
            constants.update(doc["constants"] or {})
        for name, s in (doc.get("structs") or {}).items():
            if name in structs:
                problems.append(f"{rel}: struct {name} also defined in {structs[name][0]}")
            structs[name] = (rel, s)
        for name, e in (doc.get("enums") or {}).items():
            if name in enums:
                problems.append(f"{rel}: enum {name} defined twice")
            enums[name] = e

    for cname, cval in constants.items():
        if not isinstance(cval, dict) or not any(VARIANT_RE.match(k) for k in cval):
            problems.append(f"constant {cname}: must map variant keys to ints")
            continue
        for k, v in cval.items():
            if k in ("seed_line", "reconstruction"):
                continue
            if not VARIANT_RE.match(k) or not isinstance(v, int):
                problems.append(f"constant {cname}: bad entry {k}: {v!r}")

    for ename, e in enums.items():
        where = f"enum {ename}"
        if not isinstance(e, dict) or not isinstance(e.get("values"), list):
            problems.append(f"{where}: needs a 'values' list")
            continue
        flags = e.get("kind") == "flags"
        if "complete" in e and not isinstance(e["complete"], bool):
            problems.append(f"{where}: complete must be true or false")
        seen: set[int] = set()
        for v in e["values"]:
            key = "bit" if flags else "value"
            if flags and isinstance(v, dict) and "bits" in v:  # a multi-bit field of a flag word
                from eyeq_spi.catalog.tables import flag_field_problems

                problems += [f"{where}: {p}" for p in flag_field_problems(v, seen)]
                continue
            if not isinstance(v, dict) or not isinstance(v.get(key), int):
                problems.append(f"{where}: entry without int {key}: {v!r}")
                continue
            if not isinstance(v.get("name"), str) or not v["name"]:
                problems.append(f"{where}: entry {v[key]} without a name")
            if v[key] in seen:
                problems.append(f"{where}: {key} {v[key]} repeated")
            seen.add(v[key])

    for sname, (rel, s) in structs.items():
        where = f"{rel}: struct {sname}"
        if not isinstance(s, dict):
            problems.append(f"{where}: must be a mapping")
            continue
        for k in set(s) - STRUCT_KEYS:
            problems.append(f"{where}: unknown key {k!r}")
        variants = s.get("variants")
        if not isinstance(variants, dict) or not variants:
            problems.append(f"{where}: needs variants")
            continue
        for vname, var in variants.items():
            vwhere = f"{where} variant {vname}"
            if not VARIANT_RE.match(str(vname)):
                problems.append(f"{vwhere}: variant key must look like sw5 or sw8_1")
            if not isinstance(var, dict):
                problems.append(f"{vwhere}: must be a mapping")
                continue
            for k in set(var) - VARIANT_KEYS:
                problems.append(f"{vwhere}: unknown key {k!r}")
            if not isinstance(var.get("seed_line"), int):
                problems.append(f"{vwhere}: needs an int seed_line")
            members = var.get("members")
            if not isinstance(members, list) or not members:
                problems.append(f"{vwhere}: needs a non-empty members list")
                continue
            names: set[str] = set()
            for m in members:
                if not isinstance(m, dict):
                    problems.append(f"{vwhere}: member {m!r} is not a mapping")
                    continue
                mname = m.get("name")
                mwhere = f"{vwhere} member {mname}"
                if not isinstance(mname, str) or not NAME_RE.match(mname):
                    problems.append(f"{mwhere}: bad name")
                    continue
                if mname in names:
                    problems.append(f"{mwhere}: duplicate name")
                names.add(mname)
                for k in set(m) - MEMBER_KEYS:
                    problems.append(f"{mwhere}: unknown key {k!r}")
                mtype = m.get("type", "uint8" if "bits" in m else None)
                if mtype not in PRIMITIVES and mtype not in structs:
                    problems.append(f"{mwhere}: unknown type {mtype!r}")
                if not isinstance(m.get("seed_line"), int):
                    problems.append(f"{mwhere}: needs an int seed_line")
                arr = m.get("array")
                if arr is not None and not (
                    (isinstance(arr, int) and arr > 0) or arr in constants
                ):
                    problems.append(f"{mwhere}: array {arr!r} is neither int nor constant")
                if "enum" in m and m["enum"] not in enums:
                    problems.append(f"{mwhere}: unknown enum {m['enum']!r}")
                for k in ("min", "max"):
                    if k in m and m[k] is not None and not _is_num(m[k]):
                        problems.append(f"{mwhere}: {k} must be a number")
                bits = m.get("bits")
                if bits is not None:
                    if (not isinstance(bits, list) or len(bits) != 2
                            or not all(isinstance(b, int) for b in bits) or bits[0] > bits[1]):
                        problems.append(f"{mwhere}: bits must be [lo, hi]")
                        continue
                    if mtype not in BITFIELD_CONTAINERS:
                        problems.append(f"{mwhere}: bitfield container {mtype!r}")
                    elif bits[1] >= CONTAINER_BITS[mtype]:
                        problems.append(f"{mwhere}: bits {bits} exceed {mtype}")
                    if arr is not None:
                        problems.append(f"{mwhere}: bitfield arrays are not supported")
            crcs = var.get("crc")
            if crcs is None:
                continue
            for crc in crcs if isinstance(crcs, list) else [crcs]:
                if not isinstance(crc, dict):
                    problems.append(f"{vwhere}: crc must be a mapping or a list of mappings")
                    continue
                if crc.get("field") not in names:
                    problems.append(f"{vwhere}: crc field {crc.get('field')!r} not a member")
                if crc.get("counter") is not None and crc.get("counter") not in names:
                    problems.append(f"{vwhere}: crc counter {crc.get('counter')!r} not a member")
                covers = crc.get("covers")
                if not isinstance(covers, list) or not covers:
                    problems.append(f"{vwhere}: crc needs a covers list")
                else:
                    for c in covers:
                        if not isinstance(c, str) or c.split(".")[0].split("[")[0] not in names:
                            problems.append(f"{vwhere}: crc covers unknown signal {c!r}")

    for rel, doc in docs.items():
        if not isinstance(doc, dict):
            continue
        for msg in doc.get("dasp") or []:
            where = f"{rel}: message {msg.get('name') if isinstance(msg, dict) else msg!r}"
            if not isinstance(msg, dict):
                problems.append(f"{where}: must be a mapping")
                continue
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
            if not _is_num(msg.get("rate_hz")):
                problems.append(f"{where}: rate_hz must be a number")
        for iname, im in (doc.get("init_messages") or {}).items():
            where = f"{rel}: init message {iname}"
            if not isinstance(im, dict) or not isinstance(im.get("id"), int):
                problems.append(f"{where}: needs an int id")
                continue
            for vname, var in (im.get("variants") or {}).items():
                vwhere = f"{where} variant {vname}"
                if not VARIANT_RE.match(str(vname)):
                    problems.append(f"{vwhere}: bad variant key")
                sigs = var.get("signals") if isinstance(var, dict) else None
                if not isinstance(sigs, list) or not sigs:
                    problems.append(f"{vwhere}: needs signals")
                    continue
                used: dict[int, str] = {}
                snames: set[str] = set()
                for sig in sigs:
                    swhere = f"{vwhere} signal {sig.get('name')}"
                    for k in set(sig) - SIGNAL_KEYS:
                        problems.append(f"{swhere}: unknown key {k!r}")
                    if sig.get("name") in snames:
                        problems.append(f"{swhere}: duplicate name")
                    snames.add(sig.get("name"))
                    if not isinstance(sig.get("start"), int) or not isinstance(
                        sig.get("length"), int
                    ) or sig["length"] < 1:
                        problems.append(f"{swhere}: needs int start and length")
                        continue
                    for k in ("factor", "offset", "min", "max"):
                        if not _is_num(sig.get(k)):
                            problems.append(f"{swhere}: {k} must be a number")
                    if _is_num(sig.get("factor")) and sig["factor"] == 0:
                        problems.append(f"{swhere}: factor 0")
                    for b in range(sig["start"], sig["start"] + sig["length"]):
                        if b in used:
                            problems.append(f"{swhere}: bit {b} overlaps {used[b]}")
                            break
                        used[b] = sig["name"]
    from eyeq_spi.catalog.tables import validate_tables  # GPIO, NVM, DASP header, decisions, MESP

    problems += validate_tables(docs)
    from eyeq_spi.catalog.can import validate_can_docs  # specs/can/ (seeds 000, 001, 003)

    problems += validate_can_docs(docs)
    return problems


def main(argv: list[str]) -> int:
    root = Path(argv[1] if len(argv) > 1 else "specs")
    problems = validate_tree(root)
    for p in problems:
        print(p)
    print(f"{len(problems)} problem(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
