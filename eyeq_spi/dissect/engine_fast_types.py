"""The fast path's vocabulary (:mod:`eyeq_spi.dissect.engine_fast`, in front of
:class:`~eyeq_spi.dissect.engine.Dissector`): the items it yields, a direction's span state and
the transfers of a span."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.dissect.engine_fast_frames import FrameBlock

Item = dict[str, Any] | FrameBlock
Frame = tuple[bytes, float | None, int, int]  # transfer, time, NUM, capture index


@dataclass
class Unit:
    """One transfer of a span: its first and last index into the direction's rows."""

    ks: int  # first index into the plan's rows
    ke: int  # one past the last
    first: bool


@dataclass
class Dir:
    """One direction's mode (reference or fast) and its span's state."""

    name: str | None
    code: int
    fast: bool = False
    canonical: bool = False  # reference mode: the last fed frame completed a message
    # the span in the current chunk
    units: list[Unit] = field(default_factory=list)
    ui: int = 0  # next unit to emit
    stop_k: int = 0  # index into the plan's rows of the first frame not in the span
    open_ks: int = -1  # index into the plan's rows of the open transfer's first frame, -1: none
    switch_row: int = 0
