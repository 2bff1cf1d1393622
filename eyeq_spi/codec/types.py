"""What the codecs share: the decoded application message that every decoder returns
(``message.MessageCodec`` for DASP, 0x41 and 0x10; ``mesp.MespCodec`` for MESP, decision A).

It sits below both codecs so that neither has to import the other for it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class DecodedMessage:
    """A decoded application message: protocol, name, header, fields, errors."""

    protocol: str  # MESP | DASP | DIAG | BOOT | UNKNOWN
    name: str | None
    length: int
    header: dict[str, Any] = field(default_factory=dict)
    fields: dict[str, Any] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.errors
