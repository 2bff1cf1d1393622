"""The interface every sans-IO stack exposes to a runner (docs/STYLE.md §2)."""

from __future__ import annotations

from typing import Protocol


class Node(Protocol):
    """A node may also declare ``SELF_CONTAINED = True`` (on its own class, not inherited): its
    calls act on nothing but itself, one ``data_to_send(now)`` hands over everything due at
    ``now``, and one that hands over nothing after the first call since a touch leaves
    ``get_timer()`` unchanged. Every node: ``data_to_send(now)`` hands over nothing unless it was
    touched since its last call or ``get_timer()`` is at most ``now``. ``VirtualRunner.verify``
    checks both promises."""

    def receive_data(self, transfer: bytes, now: float) -> None: ...

    def data_to_send(self, now: float) -> list[bytes]: ...

    def get_timer(self) -> float | None: ...

    def handle_timer(self, now: float) -> None: ...
