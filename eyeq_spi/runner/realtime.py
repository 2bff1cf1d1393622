"""Real-time runner: one node, one adapter, the monotonic clock."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable

from eyeq_spi import garbage
from eyeq_spi.phy.base import Adapter
from eyeq_spi.runner.node import Node

IDLE_GC = 0.003  # s with nothing due: time to collect
GC_EVERY = 0.5  # s between collections

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
        idle_gc: bool = True,
    ) -> None:
        self.node = node
        self.adapter = adapter
        self.clock = clock
        self.max_wait = max_wait
        self.tap = tap
        # a GC pass can take as long as the peer's ackTimeout (eyeq_spi/garbage.py): collect
        # only when idle, and never walk what was built before the run
        self.idle_gc = idle_gc
        self._last_gc = clock()
        self._gcs = 0
        self._paused = contextlib.ExitStack()  # the collector's state to give back on close
        if idle_gc:
            self._paused.enter_context(garbage.paused(freeze=True))

    def _flush(self, now: float) -> None:
        for out in self.node.data_to_send(now):
            if self.tap is not None:
                self.tap("tx", now, out)
            self.adapter.send(out)

    def step(self) -> None:
        # what arrived while we were away arrived before the deadlines we are about to judge
        # (an ACK waiting in the adapter is taken before its frame's ackTimeout is)
        self._receive(0.0)
        now = self.clock()
        timer = self.node.get_timer()
        if timer is not None and timer <= now:
            self.node.handle_timer(now)
        self._flush(now)
        timer = self.node.get_timer()
        wait = self.max_wait
        if timer is not None:
            wait = min(self.max_wait, max(0.0, timer - self.clock()))
        if self.idle_gc and wait >= IDLE_GC and self.clock() - self._last_gc > GC_EVERY:
            self._gcs += 1
            # young generations (well under a millisecond); everything once a minute
            garbage.collect(full=self._gcs % 120 == 0)
            self._last_gc = self.clock()
            wait = 0.0 if timer is None else min(wait, max(0.0, timer - self.clock()))
        self._receive(wait)

    def _receive(self, wait: float) -> None:
        """Hand the node every transfer the adapter holds, waiting up to ``wait`` s for the
        first, and send what each one makes due at once."""
        transfer = self.adapter.recv(wait)
        while transfer is not None:
            now = self.clock()
            if self.tap is not None:
                self.tap("rx", now, transfer)
            self.node.receive_data(transfer, now)
            # the ACK goes at once: decoding the rest of a burst could outlast ackTimeout
            self._flush(self.clock())
            transfer = self.adapter.recv(0)

    def close(self) -> None:
        """Give the cyclic GC back to the process as it was before this runner (idempotent;
        a runner left open leaves the collector off for the rest of the process)."""
        self._paused.close()

    def __enter__(self) -> RealTimeRunner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def run(self, duration: float | None = None, *, stop: Callable[[], bool] | None = None) -> None:
        end = None if duration is None else self.clock() + duration
        while not (stop is not None and stop()):
            if end is not None and self.clock() >= end:
                break
            self.step()
