"""A simulated ``spidev`` over the test wire of ``simwire`` (tests only; no hardware).

It offers the part of the real package's API the product uses, with the real signatures
(``tests/test_phy_simwire_api.py`` checks it against the installed package).
"""

from __future__ import annotations

import errno
import os
import socket
from typing import Any

import simwire


class SpiDev:
    def __init__(self, bus: int | None = None, client: int | None = None) -> None:
        self._name: str | None = None
        self._endpoint: simwire.Endpoint | None = None
        self._sender: simwire.Sender | None = None
        self._mode = 0
        self._lsb = False
        self.max_speed_hz = 500_000
        self.bits_per_word = 8
        if bus is not None and client is not None:
            self.open(bus, client)

    def open(self, bus: int, device: int) -> None:
        self.open_path(f"/dev/spidev{bus}.{device}")

    def open_path(self, spidev_path: str) -> None:
        name = os.path.basename(spidev_path)
        cfg = simwire.config()
        if name in cfg["links"]:
            self._sender = simwire.Sender(name)
        elif name in cfg["links"].values():
            self._endpoint = simwire.Endpoint(name)
        else:
            raise FileNotFoundError(errno.ENOENT, "No such file or directory")
        self._name = name
        self._check()
        self._publish()

    def _publish(self) -> None:
        port = self._endpoint.port if self._endpoint is not None else None
        simwire.publish(str(self._name), self._mode, self._lsb, port)

    def _check(self) -> None:
        if self._name is None:
            raise OSError(errno.EBADF, "Bad file descriptor")
        if simwire.unplugged(self._name):
            raise OSError(errno.ENODEV, "No such device")

    @property
    def mode(self) -> int:
        return self._mode

    @mode.setter
    def mode(self, value: int) -> None:
        self._check()
        self._mode = value
        self._publish()

    @property
    def lsbfirst(self) -> bool:
        return self._lsb

    @lsbfirst.setter
    def lsbfirst(self, value: bool) -> None:
        self._check()
        if value and not simwire.config().get("spidev_lsbfirst", True):
            raise OSError(errno.EINVAL, "Invalid argument")
        self._lsb = bool(value)
        self._publish()

    def writebytes2(self, values: Any) -> None:
        self._check()
        if self._sender is None:
            raise OSError(errno.EIO, "Input/output error")  # a slave cannot clock
        self._sender.transfer(bytes(values), self._mode, self._lsb)

    def fileno(self) -> int:
        self._check()
        if self._endpoint is None:
            raise OSError(errno.EBADF, "Bad file descriptor")
        sock: socket.socket = self._endpoint.sock
        return sock.fileno()

    def close(self) -> None:
        simwire.close(self._endpoint, self._sender)
        self._endpoint = self._sender = None
