"""MESP requests and replies built from ``specs/mesp.yaml`` (decisions M1-M3)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from construct import (
    Const,
    GreedyBytes,
    Int8ul,
    Int16ul,
    Int32ul,
    PascalString,
    Prefixed,
    Struct,
    Terminated,
)
from construct.core import ConstructError

from eyeq_spi.errors import CodecError
from eyeq_spi.spec.catalog import Catalog, MespFunction

if TYPE_CHECKING:
    from eyeq_spi.codec.message import DecodedMessage

MESP_PROTOCOL = 0x5E
REPLY_BIT = 0x80
TAG_MASK = 0x3F

PARAM = {
    "u8": Int8ul, "u16": Int16ul, "u32": Int32ul,
    "string": PascalString(Int32ul, "ascii"),
    "bytes": Prefixed(Int32ul, GreedyBytes),
}

HEADER = Struct(
    "service" / Int8ul,
    "protocol" / Const(MESP_PROTOCOL, Int8ul),
    "service_repeat" / Int8ul,
    "function" / Int8ul,
    "tag" / Int8ul,
)


@dataclass(frozen=True)
class MespHeader:
    service: int
    function: int
    tag: int

    @property
    def counter(self) -> int:
        return self.tag & TAG_MASK

    @property
    def reply(self) -> bool:
        return bool(self.tag & REPLY_BIT)


class MespCodec:
    def __init__(self, cat: Catalog) -> None:
        self.functions = {(f.service, f.function): f for f in cat.mesp}
        self.by_name = {f.name: f for f in cat.mesp}
        self.ret_names = cat.mesp_ret
        self._req = {k: self._params(f.request) for k, f in self.functions.items()}
        self._rep = {k: self._params(f.reply) for k, f in self.functions.items()}

    @staticmethod
    def _params(params: Any) -> Any:
        return Struct(*(p.name / PARAM[p.type] for p in params), Terminated)

    def function(self, name: str) -> MespFunction:
        try:
            return self.by_name[name]
        except KeyError:
            raise CodecError(f"unknown MESP function {name}") from None

    # -- encode ------------------------------------------------------------------------------
    def header(self, f: MespFunction, tag: int) -> bytes:
        if not 0 <= tag <= 0xFF:
            raise CodecError(f"MESP tag {tag} outside 0..255")
        return bytes((f.service, MESP_PROTOCOL, f.service, f.function, tag))

    def encode_request(self, name: str, counter: int, params: dict[str, Any]) -> bytes:
        f = self.function(name)
        if not 0 <= counter <= TAG_MASK:
            raise CodecError(f"MESP tag counter {counter} outside 0..63 (M1)")
        try:
            body = self._req[(f.service, f.function)].build(params)
        except (ConstructError, KeyError, TypeError, ValueError) as exc:
            raise CodecError(f"{name} request: {exc}") from None
        return self.header(f, counter) + bytes(body)

    def encode_reply(self, name: str, counter: int, ret: int, params: dict[str, Any]) -> bytes:
        f = self.function(name)
        head = self.header(f, REPLY_BIT | (counter & TAG_MASK)) + ret.to_bytes(4, "little")
        if ret != 0:
            return head
        try:
            return head + bytes(self._rep[(f.service, f.function)].build(params))
        except (ConstructError, KeyError, TypeError, ValueError) as exc:
            raise CodecError(f"{name} reply: {exc}") from None

    # -- decode ------------------------------------------------------------------------------
    def decode(self, data: bytes) -> DecodedMessage:
        from eyeq_spi.codec.message import DecodedMessage

        out = DecodedMessage("MESP", None, len(data))
        if len(data) < 5:
            out.errors.append(f"MESP message of {len(data)} bytes has no full header")
            return out
        h = HEADER.parse(data[:5])
        hdr = MespHeader(h.service, h.function, h.tag)
        out.header = {"service": hdr.service, "function": hdr.function, "tag": hdr.tag,
                      "counter": hdr.counter, "reply": hdr.reply}
        if hdr.tag & 0x40:
            out.errors.append("MESP tag bit 6 is set (M1 says 0)")
        f = self.functions.get((hdr.service, hdr.function))
        if f is None:
            out.errors.append(
                f"unknown MESP service/function 0x{hdr.service:02X}/0x{hdr.function:02X}"
            )
            return out
        out.name = f.name
        body = data[5:]
        key = (f.service, f.function)
        try:
            if hdr.reply:
                if len(body) < 4:
                    out.errors.append("MESP reply without its 4-byte ret")
                    return out
                ret = int.from_bytes(body[:4], "little")
                out.fields["ret"] = ret
                if ret != 0 and len(body) == 4:
                    return out
                out.fields.update(_plain(self._rep[key].parse(body[4:])))
            else:
                out.fields.update(_plain(self._req[key].parse(body)))
        except ConstructError as exc:
            out.errors.append(f"{f.name}: malformed parameters: {str(exc).splitlines()[0]}")
        return out


def _plain(c: Any) -> dict[str, Any]:
    return {k: v for k, v in c.items() if not k.startswith("_")}
