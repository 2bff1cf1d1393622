"""Typed MESP results: the reply parameters of ``specs/mesp.yaml`` as dataclasses. A request
ends in a :class:`MespReply` or a :class:`MespFailure`, both plain values; :func:`unwrap`
raises ``RemoteProtocolError`` for a caller that wants an exception."""

from __future__ import annotations

from dataclasses import dataclass, fields, make_dataclass
from functools import cache
from typing import Any, TypeAlias

from eyeq_spi.catalog.messages import MespFunction
from eyeq_spi.errors import RemoteProtocolError


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
    after every attempt (``ret`` None). ``str()`` reads as the error :func:`unwrap` raises."""

    function: str
    ret: int | None
    ret_name: str
    attempts: int

    def __str__(self) -> str:
        what = f"ret {self.ret} ({self.ret_name})" if self.ret is not None else self.ret_name
        return f"{self.function}: {what} after {self.attempts} attempt(s)"


MespResult: TypeAlias = MespReply | MespFailure


def unwrap(result: MespResult) -> MespReply:
    """The reply, or raise :class:`~eyeq_spi.errors.RemoteProtocolError` for a failure."""
    if isinstance(result, MespFailure):
        raise RemoteProtocolError(str(result))
    return result


_TYPES = {"string": str, "bytes": bytes}  # every other parameter type is an integer


@cache
def reply_type(function: MespFunction) -> type:
    """The reply parameters of ``function`` (``specs/mesp.yaml``) as a frozen dataclass."""
    return make_dataclass(function.name, [(param.name, _TYPES.get(param.type, int))
                                          for param in function.reply], frozen=True)


def typed(function: MespFunction, values: dict[str, Any]) -> Any:
    cls = reply_type(function)
    names = {f.name for f in fields(cls)}
    return cls(**{k: v for k, v in values.items() if k in names})
