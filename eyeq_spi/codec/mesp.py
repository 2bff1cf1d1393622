"""MESP requests and replies built from ``specs/mesp.yaml`` (decisions M1-M3)."""

from __future__ import annotations

from typing import Any

from eyeq_spi.catalog.link import spec_file
from eyeq_spi.catalog.messages import Catalog, MespFunction
from eyeq_spi.codec.types import DecodedMessage
from eyeq_spi.errors import LocalProtocolError

_HEADER = spec_file("mesp.yaml")["mesp"]  # M1: service, protocol, service, function, tag
MESP_PROTOCOL = int(_HEADER["protocol"])
REPLY_BIT = 1 << int(_HEADER["tag_reply_bit"])
TAG_MASK = (1 << int(_HEADER["tag_counter_bits"])) - 1


def param_types() -> dict[str, Any]:
    """The construct type of each parameter type (M3): little-endian unsigned integers; string
    and bytes a u32 length, then that many bytes. Built on first use, so that a start that
    meets no MESP message never imports construct."""
    from construct import GreedyBytes, Int8ul, Int16ul, Int32ul, PascalString, Prefixed

    return {"u8": Int8ul, "u16": Int16ul, "u32": Int32ul,
            "string": PascalString(Int32ul, "ascii"), "bytes": Prefixed(Int32ul, GreedyBytes)}


class MespCodec:
    def __init__(self, cat: Catalog) -> None:
        self.functions = {(f.service, f.function): f for f in cat.mesp}
        self.by_name = {f.name: f for f in cat.mesp}
        self.ret_names = cat.mesp_ret
        self._built: dict[tuple[bool, int, int], Any] = {}  # construct Structs, on first use

    def params(self, function: MespFunction, reply: bool) -> Any:
        """The construct ``Struct`` of the parameters of ``f``'s request or reply (M3), then
        nothing more: it encodes and decodes them."""
        key = (reply, function.service, function.function)
        struct = self._built.get(key)
        if struct is None:
            from construct import Struct, Terminated  # lazy: most starts meet no MESP

            types = param_types()
            struct = self._built[key] = Struct(
                *(p.name / types[p.type]
                  for p in (function.reply if reply else function.request)), Terminated)
        return struct

    def warm_up(self) -> None:
        """Build every function's request and reply Struct now: built on first use, one
        costs milliseconds, enough to make a live peer's 10 ms ackTimeout expire (seed §6)."""
        for function in self.functions.values():
            self.params(function, False)
            self.params(function, True)

    def function(self, name: str) -> MespFunction:
        try:
            return self.by_name[name]
        except KeyError:
            raise LocalProtocolError(f"unknown MESP function {name}") from None

    # -- encode ------------------------------------------------------------------------------
    def header(self, function: MespFunction, tag: int) -> bytes:
        if not 0 <= tag <= 0xFF:
            raise LocalProtocolError(f"MESP tag {tag} outside 0..255")
        return bytes((function.service, MESP_PROTOCOL, function.service, function.function, tag))

    def encode_request(self, name: str, counter: int, params: dict[str, Any]) -> bytes:
        function = self.function(name)
        if not 0 <= counter <= TAG_MASK:
            raise LocalProtocolError(f"MESP tag counter {counter} outside 0..63 (M1)")
        from construct.core import ConstructError

        try:
            body = self.params(function, False).build(params)
        except (ConstructError, KeyError, TypeError, ValueError) as exc:
            raise LocalProtocolError(f"{name} request: {exc}") from None
        return self.header(function, counter) + bytes(body)

    def encode_reply(self, name: str, counter: int, ret: int, params: dict[str, Any]) -> bytes:
        function = self.function(name)
        head = self.header(function, REPLY_BIT | (counter & TAG_MASK)) + ret.to_bytes(4, "little")
        if ret != 0:
            return head
        from construct.core import ConstructError

        try:
            return head + bytes(self.params(function, True).build(params))
        except (ConstructError, KeyError, TypeError, ValueError) as exc:
            raise LocalProtocolError(f"{name} reply: {exc}") from None

    # -- decode ------------------------------------------------------------------------------
    def decode(self, data: bytes) -> DecodedMessage:
        out = DecodedMessage("MESP", None, len(data))
        if len(data) < 5:
            out.errors.append(f"MESP message of {len(data)} bytes has no full header")
            return out
        if data[1] != MESP_PROTOCOL:  # rule A has checked it for a classified message
            out.errors.append(f"MESP protocol byte is 0x{data[1]:02X}, not 0x{MESP_PROTOCOL:02X}")
            return out
        service, function_id, tag = data[0], data[3], data[4]
        reply = bool(tag & REPLY_BIT)
        out.header = {"service": service, "function": function_id, "tag": tag,
                      "counter": tag & TAG_MASK, "reply": reply}
        if tag & ~(REPLY_BIT | TAG_MASK):
            out.errors.append("MESP tag bit 6 is set (M1 says 0)")
        function = self.functions.get((service, function_id))
        if function is None:
            out.errors.append(f"unknown MESP service/function 0x{service:02X}/0x{function_id:02X}")
            return out
        out.name = function.name
        body = data[5:]
        if reply:
            if len(body) < 4:
                out.errors.append("MESP reply without its 4-byte ret")
                return out
            ret = int.from_bytes(body[:4], "little")
            out.fields["ret"] = ret
            if ret != 0 and len(body) == 4:
                return out
            body = body[4:]
        from construct.core import ConstructError

        try:
            parsed = self.params(function, reply).parse(body)
        except ConstructError as exc:  # the first line: construct adds the path below it
            out.errors.append(f"{function.name}: malformed parameters: {str(exc).splitlines()[0]}")
            return out
        out.fields.update((k, v) for k, v in parsed.items() if not k.startswith("_"))
        return out
