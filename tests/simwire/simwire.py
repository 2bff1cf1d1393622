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
receives on the datagram socket ``DIR/NAME.sock``; one datagram is one transfer between a
falling and a rising edge of chip select. A master whose slave is not there sends into the
void, as on a real wire. Each side publishes its mode and bit order in ``DIR/NAME.conf``; the
sender applies what the lines would do to them: bits reversed when the two bit orders differ,
the bit stream one bit late when the modes differ. ``DIR/NAME.unplugged`` unplugs a device:
every call on it fails as the real library's does.
"""

from __future__ import annotations

import json
import os
import random
import socket
import time
from pathlib import Path
from typing import Any

REVERSED = bytes(int(f"{b:08b}"[::-1], 2) for b in range(256))
WIRE_TIME_S = float(os.environ.get("SIMWIRE_WT", 128 * 8 / 10_000_000))  # 128 bytes at 10 MHz


def directory() -> Path:
    return Path(os.environ["EYEQ_SPI_SIMWIRE"])


def config() -> dict[str, Any]:
    return json.loads((directory() / "wire.json").read_text())


def unplugged(name: str) -> bool:
    return (directory() / f"{name}.unplugged").exists()


def publish(name: str, mode: int, lsb_first: bool) -> None:
    path = directory() / f"{name}.conf"
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps({"mode": mode, "lsb_first": lsb_first}))
    tmp.replace(path)


def settings_of(name: str) -> dict[str, Any] | None:
    try:
        return dict(json.loads((directory() / f"{name}.conf").read_text()))
    except (OSError, ValueError):
        return None


def count_overrun(name: str) -> None:
    """A transfer the slave ``name`` lost because its buffer stayed full (tests read
    ``DIR/NAME.overruns``)."""
    path = directory() / f"{name}.overruns"
    with path.open("a") as out:
        out.write("1\n")


def usb_delay(cfg: dict[str, Any]) -> float:
    """Half a modelled USB round trip: latency / 2 plus up to the jitter."""
    return (cfg.get("latency_us", 0) / 2 + random.uniform(0, cfg.get("jitter_us", 0))) / 1e6


class Endpoint:
    """The slave's receiving socket."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.path = directory() / f"{name}.sock"
        self.path.unlink(missing_ok=True)
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.sock.bind(str(self.path))

    def close(self) -> None:
        self.sock.close()
        self.path.unlink(missing_ok=True)


class Sender:
    """A master's side of the wire: what one transfer becomes on the lines."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.cfg = config()
        self.peer = self.cfg["links"].get(name)
        self.sent = 0
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        # a slave's buffer holds a few transfers (the datagram queue); one that stays full
        # this long has overrun and loses the transfer
        self.sock.settimeout(0.005)

    def transfer(self, data: bytes, mode: int, lsb_first: bool) -> None:
        cfg = self.cfg
        time.sleep(usb_delay(cfg))  # the transfer reaches the adapter over USB
        self.sent += 1
        short = cfg.get("cs_short_every", 0)
        if short and self.sent % short == 0:
            data = data[: cfg.get("cs_short_len", 60)]  # chip select rose early
        overrun = cfg.get("overrun_every", 0)
        if overrun and self.sent % overrun == 0:
            data = data[:40] + data[88:]  # the slave's FIFO overflowed: 48 bytes lost
        peer = settings_of(self.peer) if self.peer else None
        if peer is not None and data:
            if bool(peer["lsb_first"]) != lsb_first:
                data = data.translate(REVERSED)
            if int(peer["mode"]) != mode:  # sampled on the other edge: one bit late
                data = (int.from_bytes(data, "big") >> 1).to_bytes(len(data), "big")
            try:
                self.sock.sendto(data, str(directory() / f"{self.peer}.sock"))
            except TimeoutError:
                count_overrun(self.peer)
            except OSError:
                pass  # nobody listening: lost on the wire, as on real lines
        time.sleep(WIRE_TIME_S + usb_delay(cfg))  # clocked out, then the completion

    def close(self) -> None:
        self.sock.close()
