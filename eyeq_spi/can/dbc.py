"""DBC databases built with cantools from ``specs/can/`` (never hand-written DBC text).

One DBC message per repeated slot (``Obstacle_Data_A_0`` .. ``_12`` at 0x739 + 3*i), value
tables for enums, ``GenMsgCycleTime`` from the spec's cycle, the invalid value as cantools'
``raw_invalid``, as the signal attribute ``GenSigInvalidValue`` (the raw value a decoder sees,
two's complement for signed signals: Lane_Curvature's 8000h is -32768) and in the signal comment
with its seed line. cantools' DBC reader drops ``raw_invalid`` but keeps the attribute, so a DBC
user finds every invalid value there (``signal.dbc.attributes["GenSigInvalidValue"].value``).
The bus carries the protocol's bit rate (``BA_ "Baudrate"``).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

from eyeq_spi.catalog.can import CanMessage, CanProtocol, CanSignal, protocol
from eyeq_spi.errors import EyeqError, MissingExtra, SpecError

INVALID_ATTRIBUTE = "GenSigInvalidValue"


def require_cantools() -> Any:
    try:
        import cantools
    except ImportError as exc:
        raise MissingExtra("can", "CAN output needs cantools and python-can") from exc
    return cantools


def _dbc_classes() -> tuple[Any, Any, Any]:
    """(attribute, attribute definition, DbcSpecifics) classes: cantools 45 renamed them
    (``DbcAttribute``, cantools PR 807); cantools >= 39 (our pin) has the old names."""
    try:
        from cantools.database.can.formats import dbc as new

        return new.DbcAttribute, new.DbcAttributeDefinition, new.DbcSpecifics
    except (ImportError, AttributeError):  # cantools < 45
        from importlib import import_module

        attr = import_module("cantools.database.can.attribute").Attribute
        adef = import_module("cantools.database.can.attribute_definition").AttributeDefinition
        spec = import_module("cantools.database.can.formats.dbc_specifics").DbcSpecifics
        return attr, adef, spec


def _invalid_definition() -> Any:
    """``BA_DEF_ SG_ "GenSigInvalidValue" INT``: no default, so a signal without the attribute
    has no invalid value (a default would give every signal one)."""
    _, definition, _ = _dbc_classes()
    return definition(INVALID_ATTRIBUTE, kind="SG_", type_name="INT",
                                  minimum=-(1 << 31), maximum=(1 << 31) - 1)


def _signal(s: CanSignal, enums: dict[str, dict[int, str]], seed: str,
            invalid_def: Any) -> Any:
    from collections import OrderedDict

    from cantools.database.can import Signal
    from cantools.database.conversion import BaseConversion

    attribute, _, specifics_cls = _dbc_classes()

    choices: Any = OrderedDict(sorted(enums[s.enum].items())) if s.enum else None
    notes = [f"seed {seed} line {s.seed_line}"]
    if s.description:
        notes.append(s.description)
    specifics = None
    if s.invalid is not None and s.invalid_means is not None:
        # C8: the printed invalid value is also a normal state, so no invalid attribute
        notes.append(f"printed invalid raw 0x{s.invalid:X} also means {s.invalid_means}: "
                     "not an invalid marker")
    elif s.invalid is not None:
        notes.append(f"invalid raw 0x{s.invalid:X}")
        specifics = specifics_cls(attributes=OrderedDict(
            {INVALID_ATTRIBUTE: attribute(s.raw_invalid, invalid_def)}))
    return Signal(
        name=s.name, start=s.start, length=s.length,
        byte_order="big_endian" if s.byte_order == "big_endian" else "little_endian",
        is_signed=s.signed, raw_invalid=s.reported_invalid,
        conversion=BaseConversion.factory(scale=s.scale, offset=s.offset, choices=choices,
                                          is_float=s.is_float),
        minimum=s.min, maximum=s.max, unit=s.unit, comment="; ".join(notes),
        dbc_specifics=specifics,
    )


def _message(m: CanMessage, slot: int | None, fid: int, name: str, proto: CanProtocol,
             invalid_def: Any) -> Any:
    from cantools.database.can import Message

    seed = m.seed or proto.seed  # the seed the line numbers count in
    where = f"seed {seed} section {m.section} line {m.seed_line}"
    if slot is not None and m.slots is not None:
        where += f"; slot {slot} of {m.slots.rule}"
    return Message(frame_id=fid, name=name, length=m.dlc,
                   signals=[_signal(s, proto.enums, s.seed or seed, invalid_def)
                            for s in m.signals],
                   cycle_time=round(m.cycle_ms), comment=where, senders=["EyeQ_Gateway"],
                   strict=True)


def build_database(proto: CanProtocol | str) -> Any:
    """A cantools ``Database`` of every message instance of ``proto``."""
    cantools = require_cantools()
    p = protocol(proto) if isinstance(proto, str) else proto
    from collections import OrderedDict

    from cantools.database.can import Bus, Node

    _, _, specifics_cls = _dbc_classes()

    invalid_def = _invalid_definition()
    msgs = [_message(m, slot, fid, name, p, invalid_def) for m in p.messages
            for slot, fid, name in m.instances()]
    try:
        db = cantools.database.can.Database(
            messages=msgs, nodes=[Node("EyeQ_Gateway")], version=f"eyeq-spi {p.name}",
            buses=[Bus(p.name, baudrate=p.bitrate)],
            dbc_specifics=specifics_cls(attribute_definitions=OrderedDict(
                {INVALID_ATTRIBUTE: invalid_def})))
        db.refresh()
    except Exception as exc:  # cantools rejects an inconsistent layout: a spec error
        raise SpecError(f"specs/can/{p.name}.yaml does not build a DBC: {exc}") from exc
    return db


@cache
def database(name: str) -> Any:
    """The cached database of a protocol (the gateway and the decoder share it)."""
    return build_database(name)


def dbc_text(name: str) -> str:
    """The DBC file text of protocol ``name``, as cantools writes it."""
    return str(database(name).as_dbc_string())


def write_dbc(name: str, directory: Path) -> Path:
    try:
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / f"{name}.dbc"
        path.write_text(dbc_text(name), encoding="utf-8")
    except OSError as exc:
        raise EyeqError(f"cannot write {directory}: {exc}") from exc
    return path
