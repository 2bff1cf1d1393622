"""The due heap of the simulated EyeQ's periodic DASP messages: each call of
``SimulatedEyeQ._send_due_dasp`` does O(due messages) work instead of scanning the catalogue.

The due times stay in the simulator's ``_next_dasp`` dict (name -> time), which the simulator
and its conformance mutants clear to restart the schedule; the heap mirrors it for one mode's
message list and is rebuilt whenever that dict was cleared or the mode's list changed.
"""

from __future__ import annotations

import heapq
from collections.abc import Sequence
from typing import Protocol


class _Named(Protocol):
    @property
    def name(self) -> str: ...


class DueHeap:
    """(due time, catalogue index) of the messages of one mode."""

    def __init__(self) -> None:
        self.heap: list[tuple[float, int]] = []
        self._msgs: Sequence[_Named] | None = None

    def invalidate(self) -> None:
        self._msgs = None

    def sync(self, msgs: Sequence[_Named], due: dict[str, float], now: float) -> None:
        """Rebuild from ``due`` (a missing message is due ``now``, as the scan had it) when
        ``msgs`` is not the list the heap was built for."""
        if self._msgs is not msgs:
            self._msgs = msgs
            self.heap[:] = [(due.get(m.name, now), i) for i, m in enumerate(msgs)]
            heapq.heapify(self.heap)

    def pop_due(self, now: float) -> list[tuple[float, int]]:
        """Every entry due at ``now``, in catalogue order (the order the scan sent them)."""
        out: list[tuple[float, int]] = []
        heap = self.heap
        while heap and heap[0][0] <= now:
            out.append(heapq.heappop(heap))
        out.sort(key=lambda x: x[1])
        return out

    def push(self, due_at: float, index: int) -> None:
        heapq.heappush(self.heap, (due_at, index))

    def earliest(self, due: dict[str, float], now: float) -> float:
        """``min(due.values(), default=now)``: the heap's top when it holds every due time,
        else (another mode's messages linger in ``due``) the scan's minimum."""
        if self.heap and len(due) == len(self.heap):
            return self.heap[0][0]
        return min(due.values(), default=now)
