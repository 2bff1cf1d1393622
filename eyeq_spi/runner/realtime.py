"""Real-time runner: one node, one adapter, the monotonic clock."""

from __future__ import annotations

import time
from collections.abc import Callable

from eyeq_spi.phy.base import Adapter
from eyeq_spi.runner.node import Node

Tap = Callable[[str, float, bytes], None]
"""Called for every transfer: ("tx" | "rx", time, transfer)."""


class RealTimeRunner:
    def __init__(
        self,
        node: Node,
        adapter: Adapter,
        *,
        clock: Callable[[], float] = time.monotonic,
        max_wait: float = 0.05,
        tap: Tap | None = None,
    ) -> None:
        self.node = node
        self.adapter = adapter
        self.clock = clock
        self.max_wait = max_wait
        self.tap = tap
        self.start = clock()

    def _flush(self, now: float) -> None:
        for out in self.node.data_to_send(now):
            if self.tap is not None:
                self.tap("tx", now, out)
            self.adapter.send(out)

    def step(self) -> None:
        now = self.clock()
        timer = self.node.get_timer()
        if timer is not None and timer <= now:
            self.node.handle_timer(now)
        self._flush(now)
        timer = self.node.get_timer()
        wait = self.max_wait
        if timer is not None:
            wait = min(self.max_wait, max(0.0, timer - self.clock()))
        t = self.adapter.recv(wait)
        while t is not None:
            now = self.clock()
            if self.tap is not None:
                self.tap("rx", now, t)
            self.node.receive_data(t, now)
            # send the ACK (and anything else due) at once: the peer's ackTimeout is 10 ms,
            # and decoding the rest of a burst could take longer than that
            self._flush(self.clock())
            t = self.adapter.recv(0)

    def run(self, duration: float | None = None, *, stop: Callable[[], bool] | None = None) -> None:
        end = None if duration is None else self.clock() + duration
        while not (stop is not None and stop()):
            if end is not None and self.clock() >= end:
                break
            self.step()
