"""One error tree for the whole stack (docs/STYLE.md §5).

A peer's fault met on a connection's receive path is a counted event, not an exception; these
exceptions are for what a caller must hear about: a spec that does not load, a wrong argument,
an input we cannot read, an output we cannot write, a protocol rule broken, an adapter that
fails, an optional library that is not installed. The CLI prints each as one line: exit 2 (a
failed run exits 1 by its own verdict), never a traceback.

Every public error class of the package is defined here (``tests/test_errors.py`` checks it).
Private control-flow exceptions that never leave their module stay there.

The tree::

    EyeqError
    ├── SpecError              specs/ does not load, or an entry is one the code cannot use
    ├── UsageError             a command-line argument or a caller's option is wrong
    ├── InputError             an input cannot be read: missing, foreign, damaged, empty
    │   ├── TruncatedInputError    it ends inside a transfer, block or record
    │   └── UnknownFormatError     no registered format has this name or suffix
    ├── OutputError            an output cannot be written
    ├── LocalProtocolError     we were asked to break a protocol rule or a wire format
    ├── RemoteProtocolError    the peer broke one (codecs and request results only)
    ├── AdapterError           an adapter, bus or peer service fails
    │   └── LinkLostError          the peer went away
    └── MissingExtra           an optional dependency is not installed (names the extra)
"""

from __future__ import annotations


class EyeqError(Exception):
    """Base of every error this package raises on purpose."""


class SpecError(EyeqError):
    """``specs/`` does not load or validate, or an entry of it is one the code cannot use (a
    CAN mapping expression outside the language, a layout the Wireshark generator cannot
    write). The message names the file and the entry."""


class UsageError(EyeqError):
    """A command-line argument, or an option a caller passed, is wrong: a bad name, a value out
    of range, options that exclude each other, an output name with the wrong suffix."""


class InputError(EyeqError):
    """An input cannot be read: a capture, logic-analyzer file, CAN log, DBC, scenario or
    directory that is missing, foreign, damaged, empty or without what the command needs."""


class TruncatedInputError(InputError):
    """The input ends inside a transfer, block or record (a copy cut short, a killed writer);
    what came before the cut has been read. For a capture, the file ends ``ignored`` bytes into
    the block that starts at byte ``at``; for a CAN log, ``frames`` frames were read."""

    def __init__(self, message: str, *, ignored: int = 0, at: int = 0, frames: int = 0) -> None:
        super().__init__(message)
        self.ignored = ignored
        self.at = at
        self.frames = frames


class UnknownFormatError(InputError):
    """No registered format has this name or suffix (the message lists the known ones)."""


class OutputError(EyeqError):
    """An output cannot be written: a capture, table, export, plot, screenshot, NVM file, CAN
    log or the sigrok decoder's directory (unwritable, full, vanished)."""


class LocalProtocolError(EyeqError):
    """We were asked to break a protocol rule or a wire format: send a message longer than the
    peer accepts, encode a value outside its field's range or length, or decode bytes of the
    wrong size for their layout. Raised by codecs and connections; a receive path that meets
    it in the peer's bytes counts it as that peer's fault."""


class RemoteProtocolError(EyeqError):
    """The peer broke a protocol rule: a transfer that is not a link frame, or a MESP request
    that failed (a reply with non-zero ``ret`` (decision M2), a malformed reply, or no reply
    after every attempt, raised from its ``MespFailure``). Raised by codecs and by
    ``MespFailure.exception``; connections count the peer's faults instead."""


class AdapterError(EyeqError):
    """An adapter, bus or peer service fails: a port that will not open, an address outside the
    grammar (phy/address.py), a CAN bus that cannot be opened or read, a scheduler or host that
    does not answer."""


class LinkLostError(AdapterError):
    """The peer went away: its end of the byte stream closed, reset or stopped reading."""


class MissingExtra(EyeqError):  # noqa: N818 - the name says what it is
    """A feature needs an optional dependency that is not installed: ``extra`` names the
    ``pip install 'eyeq-spi[EXTRA]'`` that brings it, ``what`` says what needs it."""

    def __init__(self, extra: str, what: str) -> None:
        super().__init__(f"{what}: pip install 'eyeq-spi[{extra}]'")
        self.extra = extra
        self.what = what
