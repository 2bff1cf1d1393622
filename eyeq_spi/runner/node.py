"""The interface every sans-IO stack exposes to a runner (docs/STYLE.md §2)."""

from __future__ import annotations

from typing import Protocol


class Node(Protocol):
    """A node may also declare ``SELF_CONTAINED = True`` (an attribute of its own class, not
    inherited; read once by :class:`~eyeq_spi.runner.virtual.VirtualRunner`): its calls act on
    nothing but itself, and once ``data_to_send`` has been called after a ``receive_data`` or
    ``handle_timer``, a call that hands over nothing leaves ``get_timer()`` unchanged; one
    ``data_to_send(now)`` call hands over everything due at ``now``. The runner then re-asks only
    this node after touching it; without it, every node.

    Every node: ``data_to_send(now)`` hands over nothing unless the node was touched since its
    last call or ``get_timer()`` is at most ``now`` (the runner does not ask it otherwise).
    ``VirtualRunner.verify`` checks both promises."""

    def receive_data(self, transfer: bytes, now: float) -> None: ...

    def data_to_send(self, now: float) -> list[bytes]: ...

    def get_timer(self) -> float | None: ...

    def handle_timer(self, now: float) -> None: ...
