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
from eyeq_spi.errors import MissingExtra, OutputError, SpecError

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


def _signal(sig: CanSignal, enums: dict[str, dict[int, str]], seed: str,
            invalid_def: Any) -> Any:
    from collections import OrderedDict

    from cantools.database.can import Signal
    from cantools.database.conversion import BaseConversion

    attribute, _, specifics_cls = _dbc_classes()

    choices: Any = OrderedDict(sorted(enums[sig.enum].items())) if sig.enum else None
    notes = [f"seed {seed} line {sig.seed_line}"]
    if sig.description:
        notes.append(sig.description)
    specifics = None
    if sig.invalid is not None and sig.invalid_means is not None:
        # C8: the printed invalid value is also a normal state, so no invalid attribute
        notes.append(f"printed invalid raw 0x{sig.invalid:X} also means {sig.invalid_means}: "
                     "not an invalid marker")
    elif sig.invalid is not None:
        notes.append(f"invalid raw 0x{sig.invalid:X}")
        specifics = specifics_cls(attributes=OrderedDict(
            {INVALID_ATTRIBUTE: attribute(sig.raw_invalid, invalid_def)}))
    return Signal(
        name=sig.name, start=sig.start, length=sig.length,
        byte_order="big_endian" if sig.byte_order == "big_endian" else "little_endian",
        is_signed=sig.signed, raw_invalid=sig.reported_invalid,
        conversion=BaseConversion.factory(scale=sig.scale, offset=sig.offset, choices=choices,
                                          is_float=sig.is_float),
        minimum=sig.min, maximum=sig.max, unit=sig.unit, comment="; ".join(notes),
        dbc_specifics=specifics,
    )


def _message(msg: CanMessage, slot: int | None, fid: int, name: str, proto: CanProtocol,
             invalid_def: Any) -> Any:
    from cantools.database.can import Message

    seed = msg.seed or proto.seed  # the seed the line numbers count in
    where = f"seed {seed} section {msg.section} line {msg.seed_line}"
    if slot is not None and msg.slots is not None:
        where += f"; slot {slot} of {msg.slots.rule}"
    return Message(frame_id=fid, name=name, length=msg.dlc,
                   signals=[_signal(s, proto.enums, s.seed or seed, invalid_def)
                            for s in msg.signals],
                   cycle_time=round(msg.cycle_ms), comment=where, senders=["EyeQ_Gateway"],
                   strict=True)


def build_database(proto: CanProtocol | str) -> Any:
    """A cantools ``Database`` of every message instance of ``proto``."""
    cantools = require_cantools()
    spec = protocol(proto) if isinstance(proto, str) else proto
    from collections import OrderedDict

    from cantools.database.can import Bus, Node

    _, _, specifics_cls = _dbc_classes()

    invalid_def = _invalid_definition()
    msgs = [_message(m, slot, fid, name, spec, invalid_def) for m in spec.messages
            for slot, fid, name in m.instances()]
    try:
        db = cantools.database.can.Database(
            messages=msgs, nodes=[Node("EyeQ_Gateway")], version=f"eyeq-spi {spec.name}",
            buses=[Bus(spec.name, baudrate=spec.bitrate)],
            dbc_specifics=specifics_cls(attribute_definitions=OrderedDict(
                {INVALID_ATTRIBUTE: invalid_def})))
        db.refresh()
    except Exception as exc:  # cantools rejects an inconsistent layout: a spec error
        raise SpecError(f"specs/can/{spec.name}.yaml does not build a DBC: {exc}") from exc
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
        raise OutputError(f"cannot write {directory}: {exc}") from exc
    return path
