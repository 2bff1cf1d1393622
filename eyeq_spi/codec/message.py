"""One entry point for a reassembled message (decision A): MESP, DASP, 0x41, 0x10 or unknown.

Every problem — wrong length, unknown ID, E2E mismatch, value out of its enum — is reported in
``DecodedMessage.errors``; nothing here raises for a peer's bytes.
"""

from __future__ import annotations

from typing import Any

from eyeq_spi.catalog.messages import Catalog, MessageDef, SwKey, catalog
from eyeq_spi.catalog.tables import dasp_header
from eyeq_spi.codec.e2e import E2EState, protect, verify
from eyeq_spi.codec.layout import Layout, LayoutCache
from eyeq_spi.codec.mesp import MESP_PROTOCOL, MespCodec
from eyeq_spi.codec.types import DecodedMessage as DecodedMessage  # re-exported: the result
from eyeq_spi.errors import LocalProtocolError, SpecError

DASP_PROTOCOL = dasp_header().protocol  # §7.1.2: 0x65, specs/dasp_header.yaml
# rule A after MESP, by the first byte: DASP, or the data ID of a §7.1.5 message
# (0x41 DIAG, 0x10 BOOT in specs/messages.yaml)
_FIRST_BYTE = {msg.data_id: msg.protocol for msg in catalog().messages if msg.protocol != "DASP"}
_FIRST_BYTE[DASP_PROTOCOL] = "DASP"
BOOT_ID = next(data_id for data_id, name in _FIRST_BYTE.items() if name == "BOOT")


class DaspCounters:
    """Decision D1 on the receive side: the counter of each data ID should step +1 mod 256; an
    unexpected one is reported (BadSeq) and the expected value is relearned from it."""

    def __init__(self) -> None:
        self._last: dict[int, int] = {}

    def check(self, data_id: int, counter: int) -> int | None:
        """The counter that was expected if ``counter`` is not it, else None."""
        last = self._last.get(data_id)
        self._last[data_id] = counter
        if last is not None and counter != (last + 1) & 0xFF:
            return (last + 1) & 0xFF
        return None

    def clear(self) -> None:
        self._last.clear()


def is_mesp(data: bytes) -> bool:
    """Rule A for MESP, with room for the whole 5-byte header (M1)."""
    return len(data) >= 5 and classify(data) == "MESP"


def classify(data: bytes) -> str:
    """Rule A on the first bytes of a reassembled message."""
    if len(data) >= 3 and data[1] == MESP_PROTOCOL and data[0] == data[2]:
        return "MESP"
    if not data:
        return "UNKNOWN"
    return _FIRST_BYTE.get(data[0], "UNKNOWN")


class MessageCodec:
    """Encodes and decodes every application message for one SW version."""

    def __init__(self, sw: str | None = None, cat: Catalog | None = None) -> None:
        self.cat = cat or catalog()
        self.sw: SwKey = self.cat.sw(sw)
        self.layouts = LayoutCache(self.cat)
        self.mesp = MespCodec(self.cat)
        self._other = {m.protocol: m for m in self.cat.messages if m.protocol in ("DIAG", "BOOT")}
        self._dasp: dict[int, MessageDef | None] = {}  # data ID -> message in self.sw

    def other_message(self, protocol: str) -> MessageDef | None:
        """The one message of a 0x41 (``DIAG``) or 0x10 (``BOOT``) protocol (rule A)."""
        return self._other.get(protocol)

    # -- layouts -----------------------------------------------------------------------------
    def layout(self, msg: MessageDef) -> Layout:
        return self.layouts.get(msg.payload, self.sw)

    def message(self, name: str) -> MessageDef:
        msg = self.cat.message(name)
        if msg.protocol == "DASP" and not msg.exists_in(self.sw):
            raise SpecError(f"{name} does not exist in {self.sw}")
        return msg

    def dasp_message(self, data_id: int) -> MessageDef | None:
        """The DASP message with ``data_id`` in this SW release (cached), None if unknown."""
        try:
            return self._dasp[data_id]
        except KeyError:
            msg = self._dasp[data_id] = self.cat.dasp_by_id(data_id, self.sw)
            return msg

    # -- encode ------------------------------------------------------------------------------
    def encode_payload(
        self, msg: MessageDef, fields: dict[str, Any], e2e: E2EState | None = None
    ) -> bytes:
        lay = self.layout(msg)
        buf = bytearray(lay.build(fields))
        protect(buf, lay, e2e)
        return bytes(buf)

    def encode_dasp(
        self, name: str, fields: dict[str, Any], counter: int, e2e: E2EState | None = None
    ) -> bytes:
        msg = self.message(name)
        if msg.protocol != "DASP":
            raise LocalProtocolError(f"{name} is not a DASP message")
        if not 0 <= counter <= 255:
            raise LocalProtocolError(f"DASP counter {counter} outside 0..255")
        header = bytes((DASP_PROTOCOL, msg.data_id, counter, 0))  # §7.1.2
        return header + self.encode_payload(msg, fields, e2e)

    def encode_other(self, protocol: str, fields: dict[str, Any]) -> bytes:
        """0x41 (``DIAG``) or 0x10 (``BOOT``): the ID byte, then the seed's table (rule A)."""
        msg = self._other[protocol]
        return bytes([msg.data_id]) + self.encode_payload(msg, fields)

    # -- decode ------------------------------------------------------------------------------
    def decode(
        self, data: bytes, e2e: E2EState | None = None, *, fields: bool = True
    ) -> DecodedMessage:
        """``fields=False``: a DASP message gets its header, E2E and length checks (the same
        errors) but no field values (a host with nobody listening)."""
        proto = classify(data)
        if proto == "MESP":
            return self.mesp.decode(data)
        if proto == "DASP":
            return self._decode_dasp(data, e2e, fields)
        if proto in ("DIAG", "BOOT"):
            msg = self._other[proto]
            out = DecodedMessage(proto, msg.name, len(data), {"id": data[0]})
            self._decode_payload(out, msg, data[1:], e2e)
            return out
        out = DecodedMessage("UNKNOWN", None, len(data))
        out.errors.append(
            f"unknown message: first byte 0x{data[0]:02X}" if data else "empty message"
        )
        return out

    def _decode_dasp(
        self, data: bytes, e2e: E2EState | None, fields: bool = True
    ) -> DecodedMessage:
        out = DecodedMessage("DASP", None, len(data))
        if len(data) < 4:
            out.errors.append(f"BadHdr: DASP message of {len(data)} bytes has no full header")
            return out
        # §7.1.2 header (classify() has checked the protocol byte)
        data_id, counter, reserved = data[1], data[2], data[3]
        out.header = {"data_id": data_id, "counter": counter}
        if reserved != 0:
            out.errors.append(f"DASP reserved byte is 0x{reserved:02X}, not 0")
        msg = self.dasp_message(data_id)
        if msg is None:
            out.errors.append(f"BadHdr: unknown DASP data ID 0x{data_id:02X} in {self.sw}")
            return out
        out.name = msg.name
        self._decode_payload(out, msg, data[4:], e2e, fields)
        return out

    def _decode_payload(
        self, out: DecodedMessage, msg: MessageDef, payload: bytes, e2e: E2EState | None,
        fields: bool = True,
    ) -> None:
        out.name = msg.name
        try:
            lay = self.layout(msg)
        except SpecError as exc:
            out.errors.append(str(exc))
            return
        if len(payload) != lay.size:
            what = "BadHdr: " if msg.protocol == "DASP" else ""
            out.errors.append(
                f"{what}{msg.name} payload is {len(payload)} bytes, expected {lay.size} "
                f"({self.sw})"
            )
            return
        if fields:
            out.fields = lay.parse(payload)
        out.errors += verify(payload, lay, e2e)
