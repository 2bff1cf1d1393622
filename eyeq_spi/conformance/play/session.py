"""One conformance session: our tester node behind the shim, facing the implementation under
test, in virtual time (``--builtin``: the DUT is one of our own nodes on a memory pair) or in
real time (the DUT is behind a phy adapter). A script drives it with :meth:`Session.run` and
:meth:`Session.wait`, which are the only places time advances."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from eyeq_spi.conformance.model import STALL_MIN
from eyeq_spi.conformance.play.shim import Shim
from eyeq_spi.conformance.trace import Trace
from eyeq_spi.errors import LinkLostError
from eyeq_spi.phy.base import Adapter
from eyeq_spi.phy.memory import memory_pair
from eyeq_spi.runner.node import Node
from eyeq_spi.runner.realtime import RealTimeRunner
from eyeq_spi.runner.virtual import VirtualRunner

SLICE = 0.002  # how often a waiting script looks at the trace (seconds of session time)
PROBE_LINK_TAG = 1 << 40  # link tags of raw probe frames: far above any transport message id


class Session:
    def __init__(self, trace: Trace, tester: Node, *, dut: Node | None = None,
                 adapter: Adapter | None = None) -> None:
        self.trace = trace
        self.shim = Shim(tester, trace)
        self.dut: Any = dut
        self.adapter = adapter
        self._virtual: VirtualRunner | None = None
        self._rt: RealTimeRunner | None = None
        self._last_turn: float | None = None  # real time: when the loop last came round
        self.peer_left: float | None = None  # real time: when the peer closed the link
        if dut is not None:
            shim_end, dut_end = memory_pair()
            self._virtual = VirtualRunner([(self.shim, shim_end), (dut, dut_end)])
        elif adapter is not None:
            t0 = time.monotonic()
            self._rt = RealTimeRunner(self.shim, adapter, clock=lambda: time.monotonic() - t0,
                                      max_wait=SLICE)

    @property
    def now(self) -> float:
        if self._virtual is not None:
            return self._virtual.now
        assert self._rt is not None
        return self._rt.clock()

    def run(self, seconds: float) -> None:
        self.wait(lambda: False, seconds)

    def nak_probes(self, link: Any) -> None:
        """The frames both players corrupt on purpose to provoke the DUT's NAKs (L5): a bad
        CRC, a bad D, a bad R and a NUM far outside the window, 30 ms apart; ``link`` is our
        own link connection, whose next NUM each probe takes."""
        for name, bad in (("nak_crc", {"bad_crc": True}), ("nak_format_d", {"d": 0x1}),
                          ("nak_format_r", {"r": 0x1})):
            self.shim.probe(name, num=link.next_num, **bad)
            self.run(0.03)
        self.shim.probe("nak_window", num=link.next_num + 2048)
        self.run(0.03)

    def ack_blackout(self, seconds: float, watch: float) -> None:
        """We ACK nothing for ``seconds`` (L7: the DUT's window fills, and it must not resend),
        then watch until ``watch`` seconds have passed."""
        start = self.now
        self.shim.hold_acks_until = start + seconds
        self.trace.mark(start, "ack_blackout", until=start + seconds)
        self.run(watch)
        self.trace.fault(start, start + seconds, "ack_blackout")

    def wait(self, cond: Callable[[], bool], timeout: float) -> bool:
        """Advance until ``cond()`` holds (True) or ``timeout`` seconds pass (False). Once the
        peer has left (a host that stops may close its port), time stands still: False."""
        end = self.now + timeout
        while not cond():
            if self.peer_left is not None:
                return False
            if self.now >= end - 1e-9:
                return False
            if self._virtual is not None:
                self._virtual.run_until(min(end, self._virtual.now + SLICE))
            else:
                assert self._rt is not None
                self._turn()
                try:
                    self._rt.step()
                except LinkLostError as exc:
                    self.peer_left = self.now
                    self.trace.mark(self.now, "peer_left", error=str(exc))
                    self.finish()
        return True

    def _turn(self) -> None:
        """Record a stall when the real-time loop comes round late (load.py)."""
        now = self.now
        last, self._last_turn = self._last_turn, now
        if last is not None and now - last > SLICE + STALL_MIN:
            self.trace.stalls.append((last, now))

    def finish(self) -> None:
        if self._rt is not None:
            self._rt.close()  # the collector back on (idempotent: finish may come twice)
        self.trace.end = max(self.trace.end, self.now)
