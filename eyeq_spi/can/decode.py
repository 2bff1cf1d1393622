"""Decoding CAN logs (through python-can's readers) with the protocols of ``specs/can/``, into the
record shape of ``eyeq-spi dissect --json`` (docs/can.md); values rounded to the decimals their
scale and offset have (-1.88, not -1.8800000000000001).

Decision C10: a frame whose ID the protocol does not define is another node's (name None, no
error). C11: while a lane's quality is low, the signals its rule governs are invalid, not errors;
a "B" frame takes the quality of the latest "A" frame of its lane on its channel. C8: a frame
shorter than its DLC that holds every signal is decoded and flagged ``short_dlc``; a printed
invalid value that is also a normal state (``invalid_means``) is not reported invalid.

Each :class:`MessageDecoder` is compiled once from the spec: the arithmetic cantools applies to
the DBC built from the same spec (tested frame by frame), without its per-frame dispatch."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from decimal import Decimal
from functools import cache
from typing import Any

from eyeq_spi.can.logs import read_log
from eyeq_spi.catalog.can import CanMessage, CanSignal, protocol

__all__ = ["CanDecoder", "MessageDecoder", "SignalDecoder", "human_record", "read_log",
           "table_record"]

_F32 = struct.Struct(">f")
SHORT_DECIMALS = 6  # a scale such as 0.01 or 0.0002: integer arithmetic, one division


@dataclass(frozen=True)
class SignalDecoder:
    """One signal's raw extraction from the payload as an integer (see ``shift``)."""

    spec: CanSignal
    big_endian: bool
    shift: int  # raw = (payload_int >> shift) & mask; payload_int little- or big-endian
    mask: int
    sign_bit: int  # 0 if unsigned
    scale: float
    offset: float
    integer: bool  # scale 1 and offset 0 as ints: physical values stay int (as cantools)
    low: float | None  # range with the tolerance of the printed figures
    high: float | None
    invalid: int | None  # the raw value reported invalid (C8: none when also a normal state)
    labels: dict[int, str] | None
    nbytes: int  # leading payload bytes that hold the signal
    digits: int | None  # decimals the scale and offset imply (values rounded to them)

    @classmethod
    def build(cls, sig: CanSignal, dlc: int, enums: dict[str, dict[int, str]]) -> SignalDecoder:
        big = sig.byte_order == "big_endian"
        if big:  # Motorola: start is the MSB's bit in DBC numbering; count from the left
            msb = (sig.start // 8) * 8 + (7 - sig.start % 8)
            shift = dlc * 8 - 1 - (msb + sig.length - 1)
        else:
            shift = sig.start
        integer = isinstance(sig.scale, int) and isinstance(sig.offset, int) and not sig.is_float
        return cls(sig, big, shift, (1 << sig.length) - 1,
                   1 << (sig.length - 1) if sig.signed else 0, sig.scale, sig.offset, integer,
                   None if sig.min is None else sig.min - 1e-9 * abs(sig.min),
                   None if sig.max is None else sig.max + 1e-9 * abs(sig.max),
                   sig.reported_invalid, enums.get(sig.enum) if sig.enum else None,
                   sig.covered_bytes(), None if integer or sig.is_float or (
                       _exact(sig.scale) and _exact(sig.offset))
                   else max(_decimals(sig.scale), _decimals(sig.offset)))

    def decimal(self) -> tuple[int, int, int]:
        """(scale, offset, divisor) as integers: ``(raw * scale + offset) / divisor`` is the
        value at the signal's resolution, one correctly rounded division (for a scale and an
        offset of at most ``SHORT_DECIMALS`` decimals, which these integers hold exactly)."""
        den = 10 ** (self.digits or 0)
        return (int(Decimal(repr(self.scale)) * den), int(Decimal(repr(self.offset)) * den),
                den)


def _exact(value: float) -> bool:
    """Whether ``value`` as written is exactly its binary value (0.0625, 2**-10): a raw integer
    times such a scale plus such an offset needs no rounding."""
    return Decimal(value) == Decimal(repr(value))


def _decimals(value: float) -> int:
    """How many decimals ``value`` has as written (0.02: 2, 9.765625e-07: 12): a value
    ``raw * scale + offset`` has no more, so rounding to them removes only binary noise
    (-1.8800000000000001 is -1.88)."""
    exponent = Decimal(repr(value)).as_tuple().exponent
    return max(0, -exponent) if isinstance(exponent, int) else 0


class MessageDecoder:
    """Decoder of one frame ID, compiled from its spec message."""

    def __init__(self, spec: CanMessage, name: str, enums: dict[str, dict[int, str]],
                 quality_source: int | None = None) -> None:
        self.spec = spec
        self.name = name
        self.dlc = spec.dlc
        self.signals = [SignalDecoder.build(s, spec.dlc, enums) for s in spec.signals]
        self.needed = max(s.nbytes for s in self.signals)  # C8: the shortest complete frame
        self.units = {s.name: s.unit for s in spec.signals if s.unit}
        # decision C11: the frame ID whose quality signal governs some of this one's signals
        self.quality = spec.quality
        self.quality_source = quality_source
        self.governed = frozenset(spec.quality.governs) if spec.quality else frozenset()
        self.compiled = self._compile()

    def _compile(self) -> Any:
        """Straight-line Python decoding a frame of the spec's DLC, constants inlined, built
        once from the spec (held to cantools on the DBC built from the same spec)."""
        env: dict[str, Any] = {"_F32": _F32.unpack, "_finite": math.isfinite,
                               "_fmt": _out_of_range}
        big = any(sig.big_endian for sig in self.signals)
        body = ["def _decode(data, fields, labels, invalid, errors):",
                "    le = int.from_bytes(data, 'little')"]
        if big:
            body.append("    be = int.from_bytes(data, 'big')")
        for index, sig in enumerate(self.signals):
            word = "be" if sig.big_endian else "le"
            name = sig.spec.name
            body.append(f"    r = ({word} >> {sig.shift}) & {sig.mask}" if sig.shift else
                        f"    r = {word} & {sig.mask}")
            if sig.sign_bit:
                body.append(f"    if r & {sig.sign_bit}: r -= {sig.mask + 1}")
            if sig.spec.is_float:
                body += ["    x = _F32(r.to_bytes(4, 'big'))[0]",
                         "    if not _finite(x): x = None"]
            elif sig.integer:
                expr = "r" if sig.scale == 1 and sig.offset == 0 else \
                    f"r * {int(sig.scale)} + {int(sig.offset)}"
                body.append(f"    x = {expr}")
            elif sig.digits is None:  # binary-exact scale and offset: nothing to round
                body.append(f"    x = r * {sig.scale!r} + {sig.offset!r}")
            else:
                if sig.digits > SHORT_DECIMALS:
                    body.append(f"    x = round(r * {sig.scale!r} + {sig.offset!r}, {sig.digits})")
                else:
                    num, off, den = sig.decimal()
                    body.append(f"    x = (r * {num} + {off}) / {den}")
            body.append(f"    fields[{name!r}] = x")
            if sig.labels is not None:
                env[f"_L{index}"] = sig.labels
                body.append(f"    labels[{name!r}] = _L{index}.get(r)")
            checks = []
            if sig.low is not None:
                checks.append(f"x < {sig.low!r}")
            if sig.high is not None:
                checks.append(f"x > {sig.high!r}")
            cond = " or ".join(checks)
            if sig.spec.is_float and cond:
                cond = f"x is not None and ({cond})"
            if sig.invalid is not None:
                body.append(f"    if r == {sig.invalid}: invalid.append({name!r})")
                if cond:
                    body.append(f"    elif {cond}: errors.append(_fmt({name!r}, x, "
                                f"{sig.spec.min!r}, {sig.spec.max!r}))")
            elif cond:
                body.append(f"    if {cond}: errors.append(_fmt({name!r}, x, {sig.spec.min!r}, "
                            f"{sig.spec.max!r}))")
        exec(compile("\n".join(body), f"<decoder {self.name}>", "exec"), env)
        return env["_decode"]

    def decode_other_length(self, data: bytes, rec: dict[str, Any]) -> None:
        """A frame of another length than the spec's DLC: short but holding every signal (C8)
        is flagged ``short_dlc``, any other is an error; the signals it holds are decoded."""
        count = len(data)
        errors = rec["errors"]
        if self.needed <= count < self.dlc:
            rec["short_dlc"] = True
        else:
            errors.append(f"DLC {count}, spec {self.dlc}")
        self.compiled((data + bytes(self.dlc))[:self.dlc], rec["fields"], rec["labels"],
                      rec["invalid"], errors)
        absent = {sig.spec.name for sig in self.signals if sig.nbytes > count}
        if absent:  # not in this (too short) frame
            for name in absent:
                rec["fields"].pop(name, None)
                rec["labels"].pop(name, None)
            rec["invalid"][:] = [name for name in rec["invalid"] if name not in absent]
            errors[:] = [text for text in errors if text.split(" ", 1)[0] not in absent]


def _out_of_range(name: str, value: float, lo: float | None, hi: float | None) -> str:
    return (f"{name} {value:g} outside [{'-inf' if lo is None else f'{lo:g}'}, "
            f"{'inf' if hi is None else f'{hi:g}'}]")


@cache
def _message_decoders(proto: str) -> dict[int, MessageDecoder]:
    """The compiled decoders of a protocol, by frame ID (built once per process)."""
    spec = protocol(proto)
    out = {}
    for msg in spec.messages:
        source = msg if msg.quality is None or msg.quality.message is None else \
            spec.message(msg.quality.message)
        for slot, fid, name in msg.instances():
            src = source.instances()[slot or 0][1] if msg.quality is not None else None
            out[fid] = MessageDecoder(msg, name, spec.enums, src)
    return out


def quality_marks(dec: MessageDecoder, quality: int | None, fields: dict[str, Any],
                  invalid: list[str], errors: list[str]) -> None:
    """Decision C11: below its quality, a lane's measurement signals are invalid (shown as
    sent, flagged), never errors."""
    rule = dec.quality
    if rule is None or quality is None or quality >= rule.valid_from:
        return
    for name in rule.governs:
        if name in fields and name not in invalid:
            invalid.append(name)
    if errors:
        errors[:] = [e for e in errors if e.split(" ", 1)[0] not in dec.governed]


class CanDecoder:
    """Decodes python-can messages of one protocol."""

    def __init__(self, proto: str) -> None:
        self.protocol = protocol(proto)
        self.by_id: dict[int, MessageDecoder] = _message_decoders(self.protocol.name)
        self._channels: dict[Any, str | None] = {None: None}  # Message.channel -> its text
        self._names: dict[str, MessageDecoder] | None = None
        self._quality: dict[tuple[str | None, int], int] = {}  # the latest quality (C11)

    def reset(self) -> None:
        """Forget what earlier frames said (a new log file starts)."""
        self._quality.clear()

    def column_type(self, table: str, column: str) -> str | None:
        """The Arrow type of a decoded table's column (for a column NULL in its first rows)."""
        if column in ("time",):  # seconds: relative to the log's first frame by default
            return "float64"
        if column in ("frame_index", "header.id"):
            return "int64"
        if column == "header.channel":
            return "string"
        if self._names is None:
            self._names = {d.name: d for d in self.by_id.values()}
        dec = self._names.get(table)
        for sig in dec.signals if dec is not None else ():
            if column_name(sig.spec.name, sig.spec.unit) == column:
                return "int64" if sig.integer else "float64"
        return None

    def spec_for(self, frame_id: int) -> CanMessage | None:
        hit = self.by_id.get(frame_id)
        return hit.spec if hit else None

    def decode(self, msg: Any, index: int) -> dict[str, Any]:
        """The record of one python-can message."""
        fid = msg.arbitration_id
        data = msg.data
        ch = msg.channel
        try:
            chs = self._channels[ch]
        except KeyError:
            chs = self._channels[ch] = str(ch)
        except TypeError:  # an unhashable channel object
            chs = str(ch)
        fields: dict[str, Any] = {}
        labels: dict[str, Any] = {}
        invalid: list[str] = []
        errors: list[str] = []
        dec = None if msg.is_extended_id else self.by_id.get(fid)
        rec: dict[str, Any] = {
            "kind": "message", "protocol": "CAN", "name": None if dec is None else dec.name,
            "length": len(data), "direction": None, "time": msg.timestamp, "frames": [index],
            "header": {"id": fid, "channel": chs},
            "fields": fields, "units": _NO_UNITS, "labels": labels, "invalid": invalid,
            "short_dlc": False, "errors": errors,
        }
        if dec is None:  # another node's frame (C10): no message of ours, not an error
            return rec
        if len(data) == dec.dlc:
            dec.compiled(data, fields, labels, invalid, errors)
        else:
            dec.decode_other_length(bytes(data), rec)
        rule = dec.quality
        if rule is not None:
            rec["units"] = dec.units
            if dec.quality_source == fid:
                quality = fields.get(rule.signal)
                if quality is not None:
                    self._quality[(chs, fid)] = quality
            else:
                quality = self._quality.get((chs, dec.quality_source or 0))
            quality_marks(dec, quality, fields, invalid, errors)
        elif dec.units:
            rec["units"] = dec.units
        return rec

_NO_UNITS: dict[str, str] = {}


def column_name(signal: str, unit: str | None) -> str:
    """A table column: the signal, with its unit from the spec (``View_Range [m]``)."""
    return f"{signal} [{unit}]" if unit else signal


def table_record(rec: dict[str, Any], raw_invalid: bool = False) -> dict[str, Any]:
    """``rec`` for ``--csv``/``--parquet``: columns named with their units; a value at its
    invalid value is empty (NULL), as the ``invalid`` list marks it in JSON; ``raw_invalid``
    keeps the decoded number."""
    units = rec.get("units") or _NO_UNITS
    if (raw_invalid or not rec["invalid"]) and not units:
        return rec
    invalid = () if raw_invalid else rec["invalid"]
    fields = {column_name(k, units.get(k)): None if k in invalid else v
              for k, v in rec["fields"].items()}
    return {**rec, "fields": fields}


def human_record(record: dict[str, Any]) -> str:
    time = "-" if record["time"] is None else f"{record['time']:.6f}"
    head = (f"{record['frames'][0]:8d} {time:>14s} 0x{record['header']['id']:03X} "
            f"{record['name'] or '?':24s}")
    parts = []
    units = record.get("units") or _NO_UNITS
    for name, value in record["fields"].items():
        text = f"{value:.6g}" if isinstance(value, float) else str(value)
        if name in units:
            text += f" {units[name]}"
        label = record["labels"].get(name)
        if label:
            text += f" ({label})"
        if name in record["invalid"]:
            text += " (invalid)"
        parts.append(f"{name}={text}")
    if record.get("short_dlc"):
        parts.append(f"(short DLC {record['length']})")
    if record["errors"]:
        parts.append(f"!! {'; '.join(record['errors'])}")
    return pack(head.rstrip(), parts)


def pack(head: str, items: list[str], width: int = 80, indent: int = 9) -> str:
    """``head`` then ``items`` separated by spaces, folded between items to ``width`` columns
    (continuation lines indented); an item longer than a line gets a line of its own."""
    lines, line = [], head
    for item in items:
        if len(line) + 1 + len(item) > width and line.strip():
            lines.append(line)
            line = " " * indent + item
        else:
            line = f"{line} {item}" if line else item
    lines.append(line)
    return "\n".join(lines)
