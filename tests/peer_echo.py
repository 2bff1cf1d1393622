"""A separate process: an EyeQ-role transport stack on a TCP listener that echoes every message.

Run as ``python -m tests.peer_echo``; prints ``READY <url>`` once listening, exits after
``--idle`` seconds without traffic.
"""

from __future__ import annotations

import argparse
import sys
import time

from eyeq_spi.link import LinkConfig
from eyeq_spi.phy.tcp import TcpListenAdapter
from eyeq_spi.runner import RealTimeRunner
from eyeq_spi.runner.sched import realtime
from eyeq_spi.transport import MessageReceived, TransportConnection


class Echo:
    def __init__(self) -> None:
        self.conn = TransportConnection(LinkConfig(role="eyeq"))
        self.last = time.monotonic()

    def receive_data(self, transfer: bytes, now: float) -> None:
        self.conn.receive_data(transfer, now)
        self.last = now
        while (ev := self.conn.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                self.conn.send(ev.data, now)

    def data_to_send(self, now: float) -> list[bytes]:
        return self.conn.data_to_send(now)

    def get_timer(self) -> float | None:
        return self.conn.get_timer()

    def handle_timer(self, now: float) -> None:
        self.conn.handle_timer(now)
        while self.conn.next_event() is not None:
            pass


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--idle", type=float, default=5.0)
    ap.add_argument("--limit", type=float, default=120.0)
    args = ap.parse_args()
    adapter = TcpListenAdapter("127.0.0.1", 0, timeout=30.0)
    print(f"READY {adapter.url}", flush=True)
    if not adapter.accept(30.0):
        return 1
    node = Echo()
    runner = RealTimeRunner(node, adapter)
    start = time.monotonic()
    with realtime():  # as host and sim do (eyeq_spi/runner/sched.py)
        runner.run(
            stop=lambda: time.monotonic() - node.last > args.idle
            or time.monotonic() - start > args.limit
        )
    adapter.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
