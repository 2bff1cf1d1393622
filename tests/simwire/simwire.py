"""A simulated SPI wire between processes, for tests only: the ``spidev`` and ``ft4222``
modules in this directory (put on ``PYTHONPATH`` by a test) move transfers over it instead of
over real lines. Nothing here touches hardware, and the product does not know it exists.

The wire lives in the directory ``$EYEQ_SPI_SIMWIRE``. Its ``wire.json``::

    {"links": {"MASTER_DEVICE": "SLAVE_DEVICE", ...},  # which master drives which slave
     "ft4222": ["SERIAL0", "SERIAL1", ...],            # the FTDI devices, in index order
     "latency_us": 250, "jitter_us": 250,              # a modelled USB transfer
     "cs_short_every": 0, "cs_short_len": 60,          # every Nth transfer: CS rises early
     "overrun_every": 0,                               # every Nth transfer: the slave loses bytes
     "spidev_lsbfirst": true}                          # whether the spidev controller can

A device is named by its spidev path's last part (``spidev0.0``) or its FTDI serial. A slave
receives on a UDP socket on the loopback interface (its buffer holds a few thousand
transfers, as a driver's would); one datagram is one transfer between a falling and a rising
edge of chip select. A master whose slave is not there sends into the void, as on a real wire.
Each side publishes its mode, bit order (and a slave its port) in ``DIR/NAME.conf``; the
sender applies what the lines would do to them: bits reversed when the two bit orders differ,
the bit stream one bit late when the modes differ. ``DIR/NAME.unplugged`` unplugs a device:
every call on it fails as the real library's does.
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import socket
import time
from pathlib import Path
from typing import Any

REVERSED = bytes(int(f"{b:08b}"[::-1], 2) for b in range(256))
WIRE_TIME_S = 128 * 8 / 10_000_000  # a 128-byte frame at 10 MHz
QUEUED_S = 0.001  # transfers a driver holds queued before a write blocks


def directory() -> Path:
    return Path(os.environ["EYEQ_SPI_SIMWIRE"])


def config() -> dict[str, Any]:
    return json.loads((directory() / "wire.json").read_text())


def unplugged(name: str) -> bool:
    return (directory() / f"{name}.unplugged").exists()


def publish(name: str, mode: int, lsb_first: bool, port: int | None = None) -> None:
    path = directory() / f"{name}.conf"
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps({"mode": mode, "lsb_first": lsb_first, "port": port}))
    tmp.replace(path)


def settings_of(name: str) -> dict[str, Any] | None:
    try:
        return dict(json.loads((directory() / f"{name}.conf").read_text()))
    except (OSError, ValueError):
        return None


def close(*ends: Endpoint | Sender | None) -> None:
    """Close a device's receiving and sending ends (either may be absent)."""
    for end in ends:
        if end is not None:
            end.close()


class Endpoint:
    """The slave's receiving socket."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        self.sock.bind(("127.0.0.1", 0))
        self.port = int(self.sock.getsockname()[1])

    def close(self) -> None:
        self.sock.close()


class Sender:
    """A master's side of the wire: what one transfer becomes on the lines."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.cfg = config()
        self.peer = self.cfg["links"].get(name)
        self.sent = 0
        self._peer: dict[str, Any] | None = None
        self.busy_until = 0.0  # perf_counter when the lines finish what was handed over
        self._read_at = float("-inf")
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def peer_settings(self) -> dict[str, Any] | None:
        """The slave's published settings, read again at most every 50 ms."""
        now = time.monotonic()
        if self.peer and now - self._read_at > 0.05:
            self._peer, self._read_at = settings_of(self.peer), now
        return self._peer

    def transfer(self, data: bytes, mode: int, lsb_first: bool) -> None:
        """One transfer. Its time on the lines (a modelled USB round trip of latency plus up
        to the jitter, and 128 bytes at 10 MHz) is accounted on the wire; the call blocks when
        more than ``QUEUED_S`` of it is ahead, as a driver with a transfer queue does (a round
        trip of a millisecond or more: the transfer also reaches the lines that much later)."""
        cfg = self.cfg
        usb = (cfg.get("latency_us", 0) + random.uniform(0, cfg.get("jitter_us", 0))) / 1e6
        if usb >= QUEUED_S:
            time.sleep(usb / 2)  # a slow USB: the transfer reaches the adapter late
            usb /= 2
        self.sent += 1
        if self.sent % 100 == 0:  # progress a test waits on: DIR/NAME.sent
            (directory() / f"{self.name}.sent").write_text(str(self.sent))
        short = cfg.get("cs_short_every", 0)
        if short and self.sent % short == 0:
            data = data[: cfg.get("cs_short_len", 60)]  # chip select rose early
        overrun = cfg.get("overrun_every", 0)
        if overrun and self.sent % overrun == 0:
            data = data[:40] + data[88:]  # the slave's FIFO overflowed: 48 bytes lost
        peer = self.peer_settings()
        if peer is not None and peer.get("port") and data:
            if bool(peer["lsb_first"]) != lsb_first:
                data = data.translate(REVERSED)
            if int(peer["mode"]) != mode:  # sampled on the other edge: one bit late
                data = (int.from_bytes(data, "big") >> 1).to_bytes(len(data), "big")
            with contextlib.suppress(OSError):  # nobody listening: lost, as on real lines
                self.sock.sendto(data, ("127.0.0.1", int(peer["port"])))
        now = time.perf_counter()
        self.busy_until = max(now, self.busy_until) + usb + WIRE_TIME_S
        if self.busy_until - now > QUEUED_S:
            time.sleep(self.busy_until - now - QUEUED_S / 2)

    def close(self) -> None:
        self.sock.close()
