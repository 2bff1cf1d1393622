"""One error tree for the whole stack (docs/STYLE.md §5).

A peer's fault surfaces only on the receive path, and only as a counted event; these exceptions are
for local misuse (bad arguments, a value out of range, a spec that does not load), for files and
inputs we cannot read or write, and for adapter failures. Nothing here ever reaches a CLI user as a
traceback: the CLI catches ``EyeqError``.

Every public error class of the package is defined here (``tests/test_errors.py`` checks it), and
the module that raises it imports it, so ``from eyeq_spi.host.nvm import NvmError`` works as well.
Private control-flow exceptions that never leave their module stay there.

The tree::

    EyeqError
    ├── SpecError                      specs/ does not load
    │   └── ExprError                  a CAN mapping expression outside the language
    ├── ProtocolError                  a protocol rule broken (carries its NAK reason)
    │   ├── LocalProtocolError         we were asked to break it
    │   ├── RemoteProtocolError        the peer broke it (codecs only)
    │   │   ├── FrameError             not a link frame
    │   │   └── MalformedParamsError   a MESP parameter block that does not parse (a ValueError)
    │   └── CodecError                 a value does not fit its wire format
    ├── MespError                      a MESP request failed, raised from its MespFailure
    ├── AdapterError                   a physical adapter failed
    │   ├── LinkLostError              the peer went away
    │   ├── AddressError               an address outside the grammar
    │   ├── CanBusError                a live CAN bus cannot be opened or read
    │   └── CanOutputError             a CAN bus or log cannot be opened or written
    ├── UsageError                     a command-line argument is wrong
    ├── inputs: CaptureError (TruncatedCaptureError), InputError (TruncatedInputError,
    │   UnknownFormatError), LogicInputError, CanLogError (CanLogTruncatedError), ScenarioError,
    │   NvmError
    ├── outputs: OutputError, ExportError, InstallError, PlotError
    └── runs: MonitorError, ReplayError, FleetError, BatchUnsupportedError, CanCompareError,
        CanExtraMissingError, MissingExtraError (names the pip extra to install)
"""

from __future__ import annotations


class EyeqError(Exception):
    """Base of every error this package raises on purpose."""


# -- specs ------------------------------------------------------------------------------------
class SpecError(EyeqError):
    """``specs/`` does not load or does not validate."""


class ExprError(SpecError):
    """A CAN mapping expression uses something the language does not have (spec/can_expr.py,
    when the mapping is loaded)."""


# -- protocol ---------------------------------------------------------------------------------
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


class MalformedParamsError(RemoteProtocolError, ValueError):
    """A MESP parameter block that does not parse (codec/mesp.py ``parse_params``); the message
    is what construct's parser says in the first line of its error, so a decoded record reads the
    same either way. Still a ``ValueError``, as callers of ``parse_params`` have caught it."""


class CodecError(ProtocolError):
    """A value does not fit its wire format (range, length, enum)."""


class MespError(EyeqError):
    """A MESP request failed: a reply with non-zero ``ret`` (decision M2), a malformed reply, or
    no reply after every attempt. The client returns a plain ``MespFailure`` (mesp/replies.py);
    this exception is raised from one by ``MespFailure.exception()`` and ``unwrap``."""

    def __init__(self, function: str, ret: int | None, ret_name: str, attempts: int) -> None:
        what = f"ret {ret} ({ret_name})" if ret is not None else ret_name
        super().__init__(f"{function}: {what} after {attempts} attempt(s)")
        self.function = function
        self.ret = ret
        self.ret_name = ret_name
        self.attempts = attempts


# -- adapters ---------------------------------------------------------------------------------
class AdapterError(EyeqError):
    """A physical adapter failed (port will not open, peer went away...)."""


class LinkLostError(AdapterError):
    """The peer went away: its end of the byte stream closed, reset or stopped reading."""


class AddressError(AdapterError):
    """An address that does not follow the grammar (scheme, host, port): phy/address.py."""


class CanBusError(AdapterError):
    """A live CAN bus cannot be opened or read (can/logs.py)."""


class CanOutputError(AdapterError):
    """A CAN bus or log file cannot be opened or written (can/sinks.py)."""


class UsageError(EyeqError):
    """A command-line argument is wrong."""


# -- inputs -----------------------------------------------------------------------------------
class CaptureError(EyeqError):
    """A capture file cannot be written or read (capture/pcapng_io.py)."""


class TruncatedCaptureError(CaptureError):
    """The file ends ``ignored`` bytes into the block that starts at byte ``at``."""

    def __init__(self, message: str, ignored: int, at: int) -> None:
        super().__init__(message)
        self.ignored = ignored
        self.at = at


class InputError(EyeqError):
    """The input of a dissection is not a capture we can read: foreign, empty, damaged
    (io/plain.py)."""



class TruncatedInputError(InputError):
    """The input ends in the middle of a transfer or block (a copy cut short, a killed
    writer)."""


class UnknownFormatError(InputError):
    """No registered format has this name or suffix (the message lists the known ones)."""


class LogicInputError(EyeqError):
    """A logic-analyzer capture cannot be read (foreign, truncated, no chip select...):
    the Saleae and VCD readers (logic/)."""


class CanLogError(EyeqError):
    """A CAN log cannot be read (missing, unknown format, corrupt): can/logs.py."""


class CanLogTruncatedError(CanLogError):
    """A CAN log ends inside a record or container: what was before the cut has been read
    (``frames`` of them)."""

    def __init__(self, message: str, frames: int) -> None:
        super().__init__(message)
        self.frames = frames


class ScenarioError(EyeqError):
    """A driving scenario file is malformed (host/scenario.py)."""


class NvmError(EyeqError):
    """The host's NVM file cannot be read or written (host/nvm.py)."""


# -- outputs ----------------------------------------------------------------------------------
class OutputError(EyeqError):
    """An output directory or file of a dissection cannot be written (dissect/output.py)."""


class ExportError(EyeqError):
    """An export (MDF4, MCAP, tables) cannot be written: a missing extra, an unwritable file
    (bench/mdf.py and the exporters beside it)."""


class InstallError(EyeqError):
    """The sigrok decoder cannot be written to its directory (bench/sigrok_install.py)."""


class PlotError(EyeqError):
    """A plot cannot be made: missing library, nothing to draw, bad output name (plot/)."""


# -- runs -------------------------------------------------------------------------------------
class MonitorError(EyeqError):
    """The monitor cannot run: a missing library, a bad option, an unwritable screenshot
    (monitor/)."""


class ReplayError(EyeqError):
    """A capture cannot be replayed (no EyeQ channel in it...): bench/replay.py."""


class FleetError(EyeqError):
    """The fleet run cannot start (no captures, a missing extra, a scheduler that does not
    answer): dissect/fleet.py."""


class BatchUnsupportedError(EyeqError):
    """The batch path cannot judge these frames (an unusual CRC variant): use the exact one
    (dissect/vframes.py)."""


class CanCompareError(EyeqError):
    """The DBC to compare cannot be read (can/compare.py)."""


class CanExtraMissingError(EyeqError):
    """cantools or python-can is not installed and a CAN feature needs it (can/dbc.py,
    can/sinks.py)."""


class MissingExtraError(EyeqError):
    """A format needs an optional dependency that is not installed; ``extra`` names the
    ``pip install 'eyeq-spi[EXTRA]'`` that brings it."""

    def __init__(self, message: str, extra: str) -> None:
        super().__init__(message)
        self.extra = extra
