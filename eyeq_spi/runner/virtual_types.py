"""What the virtual runner's two loops share: the tap type and the runner state the express
instants (:mod:`eyeq_spi.runner.virtual_fast`) read and advance on behalf of
:class:`~eyeq_spi.runner.virtual.VirtualRunner` (the reference loop)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from eyeq_spi.phy.base import Adapter
from eyeq_spi.runner.node import Node

Tap = Callable[[int, float, bytes], None]
"""Called for every transfer a node puts on the wire: (node index, time, transfer). A tap may
also offer ``many(transfers)``, a list of such triples in their order: the express loop then
hands it the transfers of a message handover in one call (a capture writer encodes them as a
block); without it, each goes to the tap on its own."""


class RunnerState(Protocol):
    """The runner's clock, nodes, transfers in flight and per-node caches."""

    nodes: list[tuple[Node, Adapter]]
    latency: float
    now: float
    tap: Tap | None
    _transit: list[tuple[float, int, int, bytes]]
    _seq: int
    _max_steps: int
    _timer: list[float | None]
    _known: list[bool]
    _quiet: list[bool]
    _fresh: list[bool]
    _alone: list[bool]

    def _touch(self, i: int) -> None: ...

    def _deadline(self, i: int) -> float | None: ...

    def _pump(self, drain_all: bool = False) -> None: ...
