"""MESP requests and replies built from ``specs/mesp.yaml`` (decisions M1-M3)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from eyeq_spi.catalog.messages import Catalog, MespFunction
from eyeq_spi.codec.types import DecodedMessage
from eyeq_spi.errors import CodecError
from eyeq_spi.errors import MalformedParamsError as MalformedParamsError

MESP_PROTOCOL = 0x5E
REPLY_BIT = 0x80
TAG_MASK = 0x3F

INT_PARAMS = {"u8": 1, "u16": 2, "u32": 4}  # little-endian unsigned; string and bytes: a u32
# length, then that many bytes (M3)


def param_types() -> dict[str, Any]:
    """The construct type of each parameter type (M3): the encoders' reference. Built on first
    use, so that decoding (``dissect``) never imports construct."""
    from construct import GreedyBytes, Int8ul, Int16ul, Int32ul, PascalString, Prefixed

    return {"u8": Int8ul, "u16": Int16ul, "u32": Int32ul,
            "string": PascalString(Int32ul, "ascii"), "bytes": Prefixed(Int32ul, GreedyBytes)}


def parse_params(params: Any, body: bytes) -> dict[str, Any]:
    """The parameters ``params`` (``MespParam`` list) of ``body``, in order, then nothing more
    (M3): the parse of ``Struct(*params, Terminated)`` without construct."""
    out: dict[str, Any] = {}
    pos = 0
    n = len(body)
    for p in params:
        size = INT_PARAMS.get(p.type)
        if size is not None:
            if pos + size > n:
                raise MalformedParamsError(f"Error in path (parsing) -> {p.name}")
            out[p.name] = int.from_bytes(body[pos : pos + size], "little")
            pos += size
            continue
        if pos + 4 > n:
            raise MalformedParamsError(f"Error in path (parsing) -> {p.name}")
        length = int.from_bytes(body[pos : pos + 4], "little")
        pos += 4
        if pos + length > n:
            raise MalformedParamsError(f"Error in path (parsing) -> {p.name}")
        raw = body[pos : pos + length]
        pos += length
        if p.type == "string":
            try:
                out[p.name] = raw.decode("ascii")
            except UnicodeDecodeError:
                raise MalformedParamsError(
                    f"cannot use encoding 'ascii' to decode {raw!r}") from None
        elif p.type == "bytes":
            out[p.name] = raw
        else:
            raise MalformedParamsError(f"unknown parameter type {p.type}")
    if pos != n:
        raise MalformedParamsError("Error in path (parsing)")
    return out


@dataclass(frozen=True)
class MespHeader:
    """The 5-byte MESP header (M1): service, function and tag."""

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
        self._built: dict[tuple[bool, int, int], Any] = {}  # construct encoders, on first use

    def _encoder(self, f: MespFunction, reply: bool) -> Any:
        key = (reply, f.service, f.function)
        enc = self._built.get(key)
        if enc is None:
            from construct import Struct, Terminated  # lazy: decoding never imports construct

            types = param_types()
            enc = self._built[key] = Struct(
                *(p.name / types[p.type] for p in (f.reply if reply else f.request)), Terminated)
        return enc

    def warm_up(self) -> None:
        """Build every function's request and reply encoder now: built on first use, one
        costs milliseconds, enough to make a live peer's 10 ms ackTimeout expire (seed §6)."""
        for f in self.functions.values():
            self._encoder(f, False)
            self._encoder(f, True)

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
        from construct.core import ConstructError  # lazy: only encoders import construct

        try:
            body = self._encoder(f, False).build(params)
        except (ConstructError, KeyError, TypeError, ValueError) as exc:
            raise CodecError(f"{name} request: {exc}") from None
        return self.header(f, counter) + bytes(body)

    def encode_reply(self, name: str, counter: int, ret: int, params: dict[str, Any]) -> bytes:
        f = self.function(name)
        head = self.header(f, REPLY_BIT | (counter & TAG_MASK)) + ret.to_bytes(4, "little")
        if ret != 0:
            return head
        from construct.core import ConstructError  # lazy: only encoders import construct

        try:
            return head + bytes(self._encoder(f, True).build(params))
        except (ConstructError, KeyError, TypeError, ValueError) as exc:
            raise CodecError(f"{name} reply: {exc}") from None

    # -- decode ------------------------------------------------------------------------------
    def decode(self, data: bytes) -> DecodedMessage:
        out = DecodedMessage("MESP", None, len(data))
        if len(data) < 5:
            out.errors.append(f"MESP message of {len(data)} bytes has no full header")
            return out
        if data[1] != MESP_PROTOCOL:  # rule A has checked it for a classified message
            out.errors.append(f"MESP protocol byte is 0x{data[1]:02X}, not 0x{MESP_PROTOCOL:02X}")
            return out
        hdr = MespHeader(data[0], data[3], data[4])  # M1: service, 0x5E, service, function, tag
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
        try:
            if hdr.reply:
                if len(body) < 4:
                    out.errors.append("MESP reply without its 4-byte ret")
                    return out
                ret = int.from_bytes(body[:4], "little")
                out.fields["ret"] = ret
                if ret != 0 and len(body) == 4:
                    return out
                out.fields.update(parse_params(f.reply, body[4:]))
            else:
                out.fields.update(parse_params(f.request, body))
        except MalformedParamsError as exc:
            out.errors.append(f"{f.name}: malformed parameters: {exc}")
        return out
