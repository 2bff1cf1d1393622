"""Typed MESP results. Field names are the reply parameters of ``specs/mesp.yaml``; a test checks
that every dataclass here matches its spec entry, so the two cannot drift apart."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from eyeq_spi.errors import EyeqError


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


class MespError(EyeqError):
    """A reply with non-zero ``ret`` (decision M2), or no reply after every attempt."""

    def __init__(self, function: str, ret: int | None, ret_name: str, attempts: int) -> None:
        what = f"ret {ret} ({ret_name})" if ret is not None else ret_name
        super().__init__(f"{function}: {what} after {attempts} attempt(s)")
        self.function = function
        self.ret = ret
        self.ret_name = ret_name
        self.attempts = attempts


def typed(function: str, values: dict[str, Any]) -> Any:
    cls = REPLY_TYPES.get(function)
    if cls is None:
        return dict(values)
    names = {f.name for f in fields(cls)}
    return cls(**{k: v for k, v in values.items() if k in names})
