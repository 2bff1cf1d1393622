"""MESP server: a dispatch table over the functions of ``specs/mesp.yaml`` (decision M3).

A handler takes the decoded request parameters and returns ``(ret, reply_params)``. Unknown
service/function gets ret 2, malformed parameters ret 3 (M2); the reply echoes service, function
and counter with bit 7 set (M1).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from eyeq_spi.catalog.messages import Catalog, catalog
from eyeq_spi.codec.mesp import MESP_PROTOCOL, REPLY_BIT, TAG_MASK, MespCodec
from eyeq_spi.codec.message import is_mesp
from eyeq_spi.errors import LocalProtocolError

Handler = Callable[[dict[str, Any]], tuple[int, dict[str, Any]]]

RET_GENERAL_FAILURE = 1
RET_UNKNOWN_FUNCTION = 2
RET_BAD_PARAMETERS = 3
RET_NOT_ALLOWED = 4
RET_FILE_NOT_FOUND = 5


class MespServer:
    def __init__(self, handlers: dict[str, Handler], cat: Catalog | None = None) -> None:
        self.codec = MespCodec(cat or catalog())
        unknown = set(handlers) - set(self.codec.by_name)
        if unknown:
            raise LocalProtocolError(f"handlers for unknown MESP functions: {sorted(unknown)}")
        self.handlers = handlers
        self.requests = 0
        self.malformed = 0

    def handle(self, data: bytes) -> bytes | None:
        """Reply bytes for a request, or None if ``data`` is not a MESP request."""
        if not is_mesp(data) or data[4] & REPLY_BIT:
            return None
        self.requests += 1
        service, function, counter = data[0], data[3], data[4] & TAG_MASK
        definition = self.codec.functions.get((service, function))
        if definition is None or definition.name not in self.handlers:
            return bytes((service, MESP_PROTOCOL, service, function, REPLY_BIT | counter)) + \
                RET_UNKNOWN_FUNCTION.to_bytes(4, "little")
        decoded = self.codec.decode(data)
        if decoded.errors:
            self.malformed += 1
            return self.codec.encode_reply(definition.name, counter, RET_BAD_PARAMETERS, {})
        try:
            ret, params = self.handlers[definition.name](decoded.fields)
            return self.codec.encode_reply(definition.name, counter, ret, params)
        except LocalProtocolError:
            return self.codec.encode_reply(definition.name, counter, RET_GENERAL_FAILURE, {})
