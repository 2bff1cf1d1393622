"""pyserial adapter: any pyserial URL (``socket://``, ``loop://``, ``rfc2217://``, a pty or tty)
carries transfers COBS-framed (decision S)."""

from __future__ import annotations

import contextlib
import socket

import serial

from eyeq_spi.errors import AdapterError, LinkLostError
from eyeq_spi.phy.stream import StreamAdapter


class SerialAdapter(StreamAdapter):
    def __init__(self, url: str, *, baudrate: int = 3_000_000) -> None:
        super().__init__()
        self.url = url
        try:
            # write_timeout: no write blocks past a second (a peer that reads nothing is gone)
            self.port = serial.serial_for_url(url, baudrate=baudrate, timeout=0,
                                              write_timeout=1.0)
        except (serial.SerialException, ValueError, OSError) as exc:
            raise AdapterError(f"cannot open {url!r}: {exc}") from exc
        sock = getattr(self.port, "_socket", None)
        if isinstance(sock, socket.socket):
            # Without this, Nagle + delayed ACK hold small writes for ~40 ms: far beyond the
            # link's 10 ms ackTimeout. pyserial's socket:// does not set it.
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def _write(self, data: bytes) -> None:
        try:
            self.port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise LinkLostError(f"{self.url}: write failed: {exc}") from exc

    def _read(self, timeout: float | None) -> bytes:
        try:
            self.port.timeout = timeout
            first: bytes = self.port.read(1)
            if not first:
                return b""
            self.port.timeout = 0
            rest: bytes = self.port.read(65536)
            return first + rest
        except (serial.SerialException, OSError) as exc:
            raise LinkLostError(f"{self.url}: read failed: {exc}") from exc

    def _close_internal(self) -> None:
        with contextlib.suppress(serial.SerialException, OSError):
            self.port.close()
