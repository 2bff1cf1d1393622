"""Typed MESP results, named as the reply parameters of ``specs/mesp.yaml`` (a test holds them
equal). A request ends in a :class:`MespReply` or a :class:`MespFailure`, both plain values;
:func:`unwrap` raises ``RemoteProtocolError`` for a caller that wants an exception."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, TypeAlias

from eyeq_spi.errors import RemoteProtocolError


@dataclass(frozen=True)
class ExtendedState:
    mainState: int
    subState: int


@dataclass(frozen=True)
class Versions:
    apiVersionMajor: int
    apiVersionMinor: int
    eyeqSwVersionMajor: int
    eyeqSwVersionMinor: int


@dataclass(frozen=True)
class ApplicationSwitched:
    applicationId: int


@dataclass(frozen=True)
class FileContents:
    lastModified: int
    flags: int
    desc: str
    data: bytes


@dataclass(frozen=True)
class HashResult:
    hashType: int
    datasetType: int
    result: bytes


@dataclass(frozen=True)
class EdrAccepted:
    edr_type: int
    edr_policy: int
    edr_function: int


@dataclass(frozen=True)
class CalibrationAccepted:
    ct_type: int
    ct_stage: int
    ct_version: int


REPLY_TYPES: dict[str, type] = {
    "GetEyeQExtendedState": ExtendedState,
    "GetEyeQVersions": Versions,
    "SwitchEyeQApplication": ApplicationSwitched,
    "FFSReadFile": FileContents,
    "ComputeHash": HashResult,
    "SendParamsToCalibrationTool": EdrAccepted,
    "EventCalibrationTool": CalibrationAccepted,
}


@dataclass(frozen=True)
class MespReply:
    """A successful reply (``ret`` = 0): ``value`` is the typed result of the function."""

    function: str
    tag: int
    value: Any
    attempts: int
    latency: float


@dataclass(frozen=True)
class MespFailure:
    """A failed request, as a value: a reply with non-zero ``ret`` (decision M2; ``ret_name``
    from ``specs/mesp.yaml``), a malformed reply (``ret_name`` says what is wrong), or no reply
    after every attempt (``ret`` None). ``str()`` reads as the error :meth:`exception` gives."""

    function: str
    ret: int | None
    ret_name: str
    attempts: int

    def __str__(self) -> str:
        what = f"ret {self.ret} ({self.ret_name})" if self.ret is not None else self.ret_name
        return f"{self.function}: {what} after {self.attempts} attempt(s)"

    def exception(self) -> RemoteProtocolError:
        """The exception to raise for this failure."""
        return RemoteProtocolError(str(self))


MespResult: TypeAlias = MespReply | MespFailure


def unwrap(result: MespResult) -> MespReply:
    """The reply, or raise :class:`~eyeq_spi.errors.RemoteProtocolError` for a failure."""
    if isinstance(result, MespFailure):
        raise result.exception()
    return result


def typed(function: str, values: dict[str, Any]) -> Any:
    cls = REPLY_TYPES.get(function)
    if cls is None:
        return dict(values)
    names = {f.name for f in fields(cls)}
    return cls(**{k: v for k, v in values.items() if k in names})
