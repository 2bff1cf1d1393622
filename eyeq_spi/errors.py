"""One error tree for the whole stack (docs/STYLE.md §5).

A peer's fault surfaces only on the receive path, and only as a counted event; these exceptions are
for local misuse (bad arguments, a value out of range, a spec that does not load) and for adapter
failures. Nothing here ever reaches a CLI user as a traceback: the CLI catches ``EyeqError``.
"""

from __future__ import annotations


class EyeqError(Exception):
    """Base of every error this package raises on purpose."""


class SpecError(EyeqError):
    """``specs/`` does not load or does not validate."""


class ProtocolError(EyeqError):
    """A protocol rule was broken. ``nak_reason`` is set when the rule maps to a NAK (L5)."""

    def __init__(self, message: str, nak_reason: int | None = None) -> None:
        super().__init__(message)
        self.nak_reason = nak_reason


class LocalProtocolError(ProtocolError):
    """We were asked to do something the protocol forbids (e.g. send a 9000-byte message)."""


class RemoteProtocolError(ProtocolError):
    """The peer sent something malformed. Raised only by codecs; connections count it instead."""


class FrameError(RemoteProtocolError):
    """A transfer is not a valid link frame."""


class CodecError(ProtocolError):
    """A value does not fit its wire format (range, length, enum)."""


class AdapterError(EyeqError):
    """A physical adapter failed (port will not open, peer went away...)."""


class LinkLostError(AdapterError):
    """The peer went away: its end of the byte stream closed, reset or stopped reading."""


class UsageError(EyeqError):
    """A command-line argument is wrong."""


class InputError(EyeqError):
    """The input is not a capture we can read (foreign, empty, damaged)."""


class TruncatedInputError(InputError):
    """The input ends in the middle of a transfer or block (a copy cut short, a killed
    writer)."""


class UnknownFormatError(InputError):
    """No registered format has this name or suffix (the message lists the known ones)."""


class MissingExtraError(EyeqError):
    """A format needs an optional dependency that is not installed; ``extra`` names the
    ``pip install 'eyeq-spi[EXTRA]'`` that brings it."""

    def __init__(self, message: str, extra: str) -> None:
        super().__init__(message)
        self.extra = extra
