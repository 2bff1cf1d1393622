"""Pseudo-terminal adapter: we hold the master side; a peer opens the slave path (printed by
``eyeq-spi sim --pty``) as an ordinary serial port. COBS framing as on any byte stream (S)."""

from __future__ import annotations

import contextlib
import os
import select
import termios
import time
import tty

from eyeq_spi.errors import AdapterError
from eyeq_spi.phy.stream import StreamAdapter


class PtyAdapter(StreamAdapter):
    def __init__(self) -> None:
        super().__init__()
        try:
            self.master, self.slave = os.openpty()
            tty.setraw(self.slave, termios.TCSANOW)
        except OSError as exc:
            raise AdapterError(f"cannot open a pty: {exc}") from exc
        self.path = os.ttyname(self.slave)
        self._slave_open = True

    def accept(self, timeout: float | None = None) -> bool:
        """Wait until a peer opens the slave side (True), or ``timeout`` seconds (False).

        We close our own slave descriptor; from then on the master reports POLLHUP until
        somebody else holds the slave open.
        """
        if self._slave_open:
            os.close(self.slave)
            self._slave_open = False
        poller = select.poll()
        poller.register(self.master, select.POLLIN | select.POLLHUP)
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            events = poller.poll(50)
            if not any(ev & select.POLLHUP for _, ev in events):
                return True
            if deadline is not None and time.monotonic() >= deadline:
                return False
            time.sleep(0.02)

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(self.master, view)
            except OSError as exc:
                raise AdapterError(f"{self.path}: write failed: {exc}") from exc
            view = view[n:]

    def _read(self, timeout: float | None) -> bytes:
        ready, _, _ = select.select([self.master], [], [], timeout)
        if not ready:
            return b""
        try:
            return os.read(self.master, 65536)
        except OSError:
            time.sleep(min(timeout or 0.0, 0.02))  # EIO: no peer holds the slave open
            return b""

    def _close_internal(self) -> None:
        for fd in (self.master, self.slave) if self._slave_open else (self.master,):
            with contextlib.suppress(OSError):
                os.close(fd)
