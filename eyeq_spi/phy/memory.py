"""In-memory duplex pair. Each end is an :class:`Adapter`; a fault hook on each direction can
drop, duplicate, reorder, shorten or lengthen transfers (chip-select faults, L8)."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

from eyeq_spi.phy.base import Adapter

Mangle = Callable[[bytes], list[bytes]]
"""Maps one transfer to what the peer receives: [] drops it, [t, t] duplicates it, ..."""


class MemoryAdapter(Adapter):
    def __init__(self) -> None:
        super().__init__()
        self.inbox: deque[bytes] = deque()
        self.peer: MemoryAdapter | None = None
        self.mangle: Mangle | None = None

    def _send_internal(self, transfer: bytes) -> None:
        if self.peer is None or self.peer.closed:
            return  # nobody listening: the bytes fall on the floor, as on a real bus
        out = self.mangle(transfer) if self.mangle is not None else [transfer]
        self.peer.inbox.extend(out)

    def _recv_internal(self, timeout: float | None) -> bytes | None:
        # Memory delivery is instantaneous: a timeout never helps, so it is ignored.
        return self.inbox.popleft() if self.inbox else None


def memory_pair() -> tuple[MemoryAdapter, MemoryAdapter]:
    """Two connected ends: what ``a`` sends, ``b`` receives and vice versa."""
    left, right = MemoryAdapter(), MemoryAdapter()
    left.peer, right.peer = right, left
    return left, right
