"""Helpers shared by the Lua generators (Lua 5.2, as Wireshark 4.0 embeds it): literals, the
ProtoField and value_string registries."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from eyeq_spi.codec.layout import PRIMITIVE
from eyeq_spi.errors import SpecError

PROTO = "eyeq_spi"
"""The protocol's filter name; every field is ``eyeq_spi.<something>``."""

_ABBREV_OK = re.compile(r"^[A-Za-z0-9_.-]+$")
_NAME_BAD = re.compile(r"[^A-Za-z0-9_-]")

FLOAT_FIELD = {"real32": "float", "real64": "double"}
INT_SIZE = {name: size for name, (_, size) in PRIMITIVE.items() if name not in FLOAT_FIELD}
# D2: bool is one byte; shown as its value so 2..255 stay visible
INT_FIELD = {name: "uint8" if name == "bool" else name for name in INT_SIZE}


def lua_str(text: str) -> str:
    """A double-quoted Lua string literal; anything outside printable ASCII as ``\\ddd``."""
    out = ['"']
    for byte in text.encode("utf-8"):
        if byte == 0x22:
            out.append('\\"')
        elif byte == 0x5C:
            out.append("\\\\")
        elif 0x20 <= byte < 0x7F:
            out.append(chr(byte))
        else:
            out.append(f"\\{byte:03d}")
    out.append('"')
    return "".join(out)


def lua_int(value: int) -> str:
    """An integer literal; hexadecimal above 9 keeps masks and IDs readable."""
    if value < 0:
        return str(value)
    return f"0x{value:X}" if value > 9 else str(value)


def name_part(text: str) -> str:
    """One component of a filter name: characters Wireshark rejects become ``_``."""
    return _NAME_BAD.sub("_", text) or "_"


def value_table(values: dict[int, str]) -> str:
    """A Lua value_string table ``{[0]="A", [1]="B"}``, sorted by value."""
    items = [f"[{lua_int(k)}]={lua_str(v)}" for k, v in sorted(values.items())]
    return "{" + ", ".join(items) + "}"


@dataclass
class FieldRegistry:
    """Every ProtoField of the dissector, in registration order, keyed by filter name and
    referenced from generated Lua as ``F["<abbrev without eyeq_spi.>"]``."""

    lines: list[str] = field(default_factory=list)
    abbrevs: dict[str, str] = field(default_factory=dict)  # key -> constructor call

    def add(self, key: str, ctor: str, *args: str) -> str:
        """Define ``eyeq_spi.<key>`` with ``ProtoField.<ctor>(abbrev, args...)`` (again with the
        same arguments: the existing reference; with others: a SpecError)."""
        abbrev = f"{PROTO}.{key}"
        if not _ABBREV_OK.match(abbrev):
            raise SpecError(f"specs/: {abbrev!r} is not a valid Wireshark filter name")
        call = f"ProtoField.{ctor}({', '.join([lua_str(abbrev), *args])})"
        old = self.abbrevs.get(key)
        if old is not None:
            if old != call:
                raise SpecError(f"specs/: field {abbrev} defined twice differently: {old} and "
                                f"{call}")
            return self.ref(key)
        self.abbrevs[key] = call
        self.lines.append(f"F[{lua_str(key)}] = pf({call})")
        return self.ref(key)

    @staticmethod
    def ref(key: str) -> str:
        return f"F[{lua_str(key)}]"

    def render(self) -> str:
        return "\n".join(self.lines)


@dataclass
class ValueStrings:
    """value_string tables, emitted once each as ``E["<name>"]``."""

    lines: list[str] = field(default_factory=list)
    known: dict[str, str] = field(default_factory=dict)

    def add(self, name: str, values: dict[int, str]) -> str:
        table = value_table(values)
        old = self.known.get(name)
        if old is not None and old != table:
            raise SpecError(f"specs/: value_string {name} defined twice differently")
        if old is None:
            self.known[name] = table
            self.lines.append(f"E[{lua_str(name)}] = {table}")
        return f"E[{lua_str(name)}]"

    def render(self) -> str:
        return "\n".join(self.lines)


def int_field_args(label: str, base: str, vs: str | None, mask: int | None,
                   desc: str | None) -> list[str]:
    """Arguments after the abbreviation for ``ProtoField.uintN``/``intN``."""
    args = [lua_str(label), base, vs or "nil", lua_int(mask) if mask else "nil"]
    if desc:
        args.append(lua_str(desc))
    while args[-1] == "nil":
        args.pop()
    return args
