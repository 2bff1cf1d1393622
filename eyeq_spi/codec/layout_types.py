"""What the construct layouts (:mod:`eyeq_spi.codec.layout`) and their generated ``struct`` twin
(:mod:`eyeq_spi.codec.layout_fast`) share: a member as laid out, and the shape of a layout the
twin is generated from."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

from eyeq_spi.catalog.messages import Member


@dataclass(frozen=True)
class FieldInfo:
    """One member as laid out: for ``spec show`` and the dissector."""

    name: str
    offset: int
    size: int  # bytes of the whole member (all array elements); container size for bitfields
    type: str
    count: int | None  # array length, None if scalar
    bits: tuple[int, int] | None
    member: Member


class LayoutShape(Protocol):
    """A struct's byte layout as the fast twin reads it (``Layout`` is one)."""

    @property
    def name(self) -> str: ...

    @property
    def size(self) -> int: ...

    @property
    def fields(self) -> Sequence[FieldInfo]: ...

    @property
    def children(self) -> Mapping[str, LayoutShape]: ...
