"""Link/transport demo: a host and an EyeQ stack over an in-memory SPI pair in virtual time.

It is the first slice of ``eyeq-spi demo``; the host emulator replaces it when it lands.
"""

from __future__ import annotations

import random
import time
from typing import Any

from eyeq_spi.link.connection import LinkConfig
from eyeq_spi.phy.memory import memory_pair
from eyeq_spi.runner.virtual import VirtualRunner
from eyeq_spi.transport.connection import TransportConnection
from eyeq_spi.transport.events import MessageReceived, MessageSendFailed, MessageSent


class TrafficNode:
    """Wraps a transport connection and sends random messages at a fixed rate."""

    def __init__(self, role: str, rng: random.Random, rate: float, max_size: int) -> None:
        self.conn = TransportConnection(LinkConfig(role=role))  # type: ignore[arg-type]
        self.rng = rng
        self.period = 1.0 / rate
        self.max_size = max_size
        self.next_send = 0.0
        self.sent: dict[int, bytes] = {}
        self.received: list[bytes] = []
        self.failed_ids: set[int] = set()
        self.failed = 0
        self.confirmed = 0

    def _drain(self) -> None:
        while (ev := self.conn.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                self.received.append(ev.data)
            elif isinstance(ev, MessageSendFailed):
                self.failed += 1
                self.failed_ids.add(ev.message_id)
            elif isinstance(ev, MessageSent):
                self.confirmed += 1

    def receive_data(self, transfer: bytes, now: float) -> None:
        self.conn.receive_data(transfer, now)
        self._drain()

    def data_to_send(self, now: float) -> list[bytes]:
        return self.conn.data_to_send(now)

    def get_timer(self) -> float | None:
        t = self.conn.get_timer()
        return self.next_send if t is None else min(t, self.next_send)

    def handle_timer(self, now: float) -> None:
        self.conn.handle_timer(now)
        if now >= self.next_send:
            size = self.rng.randint(1, self.max_size)
            msg = self.rng.randbytes(size)
            self.sent[self.conn.send(msg, now)] = msg
            self.next_send = now + self.period
        self._drain()


def run_link_demo(duration: float, *, seed: int = 1, rate: float = 50.0) -> dict[str, Any]:
    rng = random.Random(seed)
    host = TrafficNode("host", rng, rate, 512)  # the EyeQ receives up to 512 bytes (§6)
    eyeq = TrafficNode("eyeq", rng, rate, 2800)  # about the size of EYEQ_VIS_OBSTACLES_MSG
    a, b = memory_pair()
    runner = VirtualRunner([(host, a), (eyeq, b)])
    t0 = time.perf_counter()
    runner.run_until(duration)
    wall = time.perf_counter() - t0

    def side(me: TrafficNode, peer: TrafficNode) -> dict[str, Any]:
        # Every message that did not fail arrived, in order and intact; a failed one may or may
        # not have arrived (its last ACK may be what was lost), but nothing else did.
        it = iter(peer.received)
        intact = True
        for mid, msg in me.sent.items():
            if mid in me.failed_ids:
                continue
            for got in it:
                if got == msg:
                    break
                if got not in me.sent.values():
                    intact = False
                    break
            else:
                intact = intact and (mid == max(me.sent))  # the last one may be in flight
        return {
            "sent": len(me.sent),
            "received": len(peer.received),
            "failed": me.failed,
            "intact": intact,
            "link": me.conn.link.counters.seed_view(),
        }

    h, e = side(host, eyeq), side(eyeq, host)
    ok = h["intact"] and e["intact"] and h["failed"] == 0 and e["failed"] == 0
    return {"host": h, "eyeq": e, "virtual_s": runner.now, "wall_s": wall, "ok": ok}
