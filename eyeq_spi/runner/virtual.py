"""Virtual-clock runner: jumps from one timer to the next, so a minute of protocol runs in
however long the CPU needs. Used by the tests and the simulation."""

from __future__ import annotations

import heapq
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from eyeq_spi.phy.base import Adapter
from eyeq_spi.runner.node import Node

Tap = Callable[[int, float, bytes], None]
"""Called for every transfer a node puts on the wire: (node index, time, transfer)."""


@dataclass(order=True)
class _InTransit:
    at: float
    seq: int
    to: int = field(compare=False)
    transfer: bytes = field(compare=False)


class VirtualRunner:
    """Runs nodes, each bound to an adapter (normally the two ends of a memory pair).

    ``latency`` is the time from a node handing over a transfer to the peer receiving it; the
    default is the wire time of 128 bytes at the seed's 10 MHz SPI clock.
    """

    def __init__(
        self,
        nodes: list[tuple[Node, Adapter]],
        *,
        latency: float = 128 * 8 / 10_000_000,
        start: float = 0.0,
        tap: Tap | None = None,
        max_steps_per_instant: int = 100_000,
    ) -> None:
        self.nodes = nodes
        self.latency = latency
        self.now = start
        self.tap = tap
        self._transit: list[_InTransit] = []
        self._seq = 0
        self._max_steps = max_steps_per_instant
        self.wall_s = 0.0  # wall-clock and CPU time spent in run_until
        self.cpu_s = 0.0

    def _pump(self) -> None:
        """Move transfers until nothing more happens at ``now``."""
        for _ in range(self._max_steps):
            progress = False
            for i, (node, adapter) in enumerate(self.nodes):
                for out in node.data_to_send(self.now):
                    progress = True
                    if self.tap is not None:
                        self.tap(i, self.now, out)
                    adapter.send(out)
                for j, (_, other) in enumerate(self.nodes):
                    if j == i:
                        continue
                    while (t := other.recv(0)) is not None:
                        # `other` received it from its peer `i` only if they are a pair; a
                        # memory pair delivers to exactly one peer, so attribute it to `j`.
                        self._seq += 1
                        item = _InTransit(self.now + self.latency, self._seq, j, t)
                        heapq.heappush(self._transit, item)
                        progress = True
            while self._transit and self._transit[0].at <= self.now:
                item = heapq.heappop(self._transit)
                self.nodes[item.to][0].receive_data(item.transfer, self.now)
                progress = True
            for node, _ in self.nodes:
                timer = node.get_timer()
                if timer is not None and timer <= self.now:
                    node.handle_timer(self.now)
                    progress = True
            if not progress:
                return
        raise RuntimeError(f"no quiescence at t={self.now}: a node keeps asking for work")

    def next_time(self) -> float | None:
        times = [t for n, _ in self.nodes if (t := n.get_timer()) is not None]
        if self._transit:
            times.append(self._transit[0].at)
        return min(times) if times else None

    def run_until(
        self, t_end: float, *, stop: Callable[[], bool] | None = None, realtime: bool = False
    ) -> float:
        """Advance to ``t_end`` (or until ``stop()`` is true). Returns the time reached.

        ``realtime`` paces virtual time to the wall clock (sleeping ahead of each event), so an
        in-process emulation runs at the speed of a real bench.
        """
        w0, c0 = time.perf_counter(), time.process_time()
        try:
            return self._run(t_end, stop, (w0, self.now) if realtime else None)
        finally:
            self.wall_s += time.perf_counter() - w0
            self.cpu_s += time.process_time() - c0

    def _run(
        self, t_end: float, stop: Callable[[], bool] | None, pace: tuple[float, float] | None
    ) -> float:
        self._pump()
        while stop is None or not stop():
            nxt = self.next_time()
            if nxt is None or nxt > t_end:
                self.now = max(self.now, t_end)
                self._pump()
                break
            if pace is not None:
                ahead = (nxt - pace[1]) - (time.perf_counter() - pace[0])
                if ahead > 0:
                    time.sleep(ahead)
            self.now = max(self.now, nxt)
            self._pump()
        return self.now

    def run_for(self, duration: float, *, stop: Callable[[], bool] | None = None) -> float:
        return self.run_until(self.now + duration, stop=stop)
