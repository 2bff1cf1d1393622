"""Pseudo-terminal adapter: we hold the master side; a peer opens the slave path (printed by
``eyeq-spi sim --pty``) as an ordinary serial port. COBS framing as on any byte stream (S)."""

from __future__ import annotations

import contextlib
import os
import select
import termios
import time
import tty

from eyeq_spi.errors import AdapterError, LinkLostError
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
        self._peer = False  # a peer holds the slave open (seen since the last accept)
        self.write_timeout = 1.0  # a peer that reads nothing for this long is gone
        os.set_blocking(self.master, False)  # no write may block past --duration

    def accept(self, timeout: float | None = None) -> bool:
        """Wait until a peer opens the slave side (True), or ``timeout`` seconds (False). Our
        own slave descriptor is closed: the master reports POLLHUP until another holds it."""
        if self._slave_open:
            os.close(self.slave)
            self._slave_open = False
        poller = select.poll()
        poller.register(self.master, select.POLLIN | select.POLLHUP)
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            events = poller.poll(50)
            if not any(ev & select.POLLHUP for _, ev in events):
                self._peer = True
                return True
            if deadline is not None and time.monotonic() >= deadline:
                return False
            time.sleep(0.02)

    def _gone(self, why: str) -> LinkLostError:
        self._peer = False
        return LinkLostError(f"{self.path}: the peer left ({why})")

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        deadline = time.monotonic() + self.write_timeout
        poller = select.poll()
        poller.register(self.master, select.POLLOUT | select.POLLHUP)
        while view:
            try:
                written = os.write(self.master, view)
            except BlockingIOError:
                written = 0
            except OSError as exc:
                raise self._gone(f"write failed: {exc}") from exc
            view = view[written:]
            if not view:
                return
            left = deadline - time.monotonic()
            events = poller.poll(max(0, int(left * 1000)))
            if any(ev & select.POLLHUP for _, ev in events):
                raise self._gone("hang-up")
            if left <= 0:
                raise self._gone(f"nothing read for {self.write_timeout} s")

    def _read(self, timeout: float | None) -> bytes:
        ready, _, _ = select.select([self.master], [], [], timeout)
        if not ready:
            return b""
        try:
            return os.read(self.master, 65536)
        except BlockingIOError:
            return b""
        except OSError as exc:  # EIO: no peer holds the slave open
            if self._peer:
                raise self._gone(str(exc)) from exc
            time.sleep(min(timeout or 0.0, 0.02))
            return b""

    def _close_internal(self) -> None:
        for fd in (self.master, self.slave) if self._slave_open else (self.master,):
            with contextlib.suppress(OSError):
                os.close(fd)
