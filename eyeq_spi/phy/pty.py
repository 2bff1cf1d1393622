"""Pseudo-terminal adapter: we hold the master side; a peer opens the slave path (printed by
``eyeq-spi sim --pty``) as an ordinary serial port. COBS framing as on any byte stream (S)."""

from __future__ import annotations

import contextlib
import os
import select
import termios
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
            return b""  # the peer closed the slave side

    def _close_internal(self) -> None:
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)
