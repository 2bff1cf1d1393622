"""TCP listener adapter (``--listen tcp://HOST:PORT``) for a peer that connects with
``--port tcp://HOST:PORT``: one connection at a time, COBS-framed transfers as the serial adapter.
A peer that leaves raises :class:`LinkLostError` once; the next call waits for a new peer."""

from __future__ import annotations

import select
import socket

from eyeq_spi.errors import AdapterError, LinkLostError
from eyeq_spi.phy.address import listen_url
from eyeq_spi.phy.stream import StreamAdapter


class TcpListenAdapter(StreamAdapter):
    def __init__(self, host: str = "127.0.0.1", port: int = 0, *, timeout: float = 5.0) -> None:
        super().__init__()
        self.timeout = timeout
        try:
            self.server = socket.create_server((host, port))
        except OSError as exc:
            raise AdapterError(f"cannot listen on {host}:{port}: {exc}") from exc
        self.address: tuple[str, int] = self.server.getsockname()[:2]
        self.conn: socket.socket | None = None
        self.write_timeout = 1.0

    @property
    def url(self) -> str:
        """The URL a peer gives to ``--port`` to reach us (a wildcard address becomes loopback,
        so the URL can be handed to ``eyeq-spi host --port`` as printed)."""
        return listen_url(self.address[0], self.address[1])

    def accept(self, timeout: float | None = None) -> bool:
        if self.conn is not None:
            return True
        wait = self.timeout if timeout is None else timeout
        ready, _, _ = select.select([self.server], [], [], wait)
        if not ready:
            return False
        conn, _ = self.server.accept()
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn.settimeout(self.write_timeout)
        self.conn = conn
        self.discard_pending()
        return True

    def _write(self, data: bytes) -> None:
        if self.conn is None and not self.accept():
            raise AdapterError(f"no peer connected to {self.url} within {self.timeout} s")
        assert self.conn is not None
        try:
            self.conn.sendall(data)
        except OSError as exc:  # reset, broken pipe, or a peer that reads nothing (timeout)
            self.drop()
            raise LinkLostError(f"peer of {self.url} went away: {exc}") from exc

    def _read(self, timeout: float | None) -> bytes:
        if self.conn is None and not self.accept(timeout if timeout is not None else None):
            return b""
        assert self.conn is not None
        ready, _, _ = select.select([self.conn], [], [], timeout)
        if not ready:
            return b""
        try:
            data = self.conn.recv(65536)
        except OSError:
            data = b""
        if not data:  # the peer closed or reset: report it; the next call waits for a new one
            self.drop()
            raise LinkLostError(f"peer of {self.url} went away")
        return data

    def drop(self) -> None:
        """Close the connection to the peer (if any) and keep listening for the next one."""
        if self.conn is not None:
            self.conn.close()
            self.conn = None
        # transfers of the peer that left, received but not yet taken, go with it: the next
        # peer is a new connection and never receives them (counted, not dropped silently)
        self.stats.left_at_link_loss += self.discard_pending()

    def _close_internal(self) -> None:
        self.drop()
        self.server.close()
