"""Physical adapters: something that carries whole SPI transfers to and from the peer.

python-can's pattern: a registry of name -> (module, class), imported only when asked for and
extensible through the ``eyeq_spi.adapters`` entry-point group; the base class checks in
:meth:`send` / :meth:`recv`, an implementation provides ``_send_internal`` and ``_recv_internal``.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from dataclasses import dataclass
from importlib.metadata import entry_points
from types import TracebackType
from typing import Any

from eyeq_spi.errors import AdapterError


@dataclass
class AdapterStats:
    transfers_sent: int = 0
    decode_errors: int = 0  # stream framing that could not be decoded (dropped, counted)
    left_at_link_loss: int = 0  # transfers received from a peer that left, never taken


class Adapter(ABC):
    """One side of one duplex SPI link: ``send`` puts a transfer on our channel, ``recv`` takes
    the next transfer from the peer's channel."""

    def __init__(self) -> None:
        self.stats = AdapterStats()
        self.closed = False

    def send(self, transfer: bytes) -> None:
        if self.closed:
            raise AdapterError("adapter is closed")
        if not transfer:
            raise AdapterError("cannot send an empty transfer")
        self._send_internal(bytes(transfer))
        self.stats.transfers_sent += 1

    def recv(self, timeout: float | None = 0.0) -> bytes | None:
        """The next transfer, or None if none arrives within ``timeout`` seconds (0 = poll)."""
        if self.closed:
            raise AdapterError("adapter is closed")
        return self._recv_internal(timeout)

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._close_internal()

    def __enter__(self) -> Adapter:
        return self

    def __exit__(
        self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    @abstractmethod
    def _send_internal(self, transfer: bytes) -> None: ...

    @abstractmethod
    def _recv_internal(self, timeout: float | None) -> bytes | None: ...

    def _close_internal(self) -> None:  # noqa: B027 - optional hook
        pass

    def line_report(self) -> dict[str, Any] | None:
        """What a run summary reports of the lines under the adapter (SPI adapters: the
        measured reply latency and overruns); None when there is nothing to say."""
        return None


# name -> (module, class). Extend with entry points in group "eyeq_spi.adapters".
ADAPTERS: dict[str, tuple[str, str]] = {
    "memory": ("eyeq_spi.phy.memory", "MemoryAdapter"),
    "serial": ("eyeq_spi.phy.serial", "SerialAdapter"),
    "tcp-listen": ("eyeq_spi.phy.tcp", "TcpListenAdapter"),
    "pty": ("eyeq_spi.phy.pty", "PtyAdapter"),
    "spi": ("eyeq_spi.phy.bench", "BenchAdapter"),  # spidev:// and ft4222:// channel pairs
}


def adapter_class(name: str) -> type[Adapter]:
    """Import the adapter class registered as ``name`` (only now)."""
    target = ADAPTERS.get(name)
    if target is None:
        for ep in entry_points(group="eyeq_spi.adapters"):
            if ep.name == name:
                cls = ep.load()
                if not (isinstance(cls, type) and issubclass(cls, Adapter)):
                    raise AdapterError(f"entry point {name!r} is not an Adapter")
                return cls
        known = ", ".join(sorted(ADAPTERS))
        raise AdapterError(f"unknown adapter {name!r} (known: {known})")
    module = importlib.import_module(target[0])
    cls = getattr(module, target[1])
    assert isinstance(cls, type) and issubclass(cls, Adapter)
    return cls


def open_url(url: str) -> Adapter:
    """Connect an adapter to an address in the grammar of :mod:`eyeq_spi.phy.address` (any
    pyserial URL, a tty or pty path, or one side on SPI lines); :func:`open_listener` listens."""
    from eyeq_spi.phy.address import is_spi, parse_connect

    if is_spi(url):
        return adapter_class("spi")(url)  # type: ignore[call-arg]
    addr = parse_connect(url, check_path=False)
    return adapter_class("serial")(addr.url)  # type: ignore[call-arg]


def open_listener(url: str, *, timeout: float = 5.0) -> Adapter:
    """A TCP listener on ``tcp://HOST:PORT`` (port 0: any free port) that serves one peer at a
    time; ``timeout`` bounds the wait for a peer on the first send or receive. One side on SPI
    lines (as :func:`open_url` takes it) is there at once: the peer is on the wires."""
    from eyeq_spi.phy.address import is_spi, parse_listen

    if is_spi(url):
        return adapter_class("spi")(url)  # type: ignore[call-arg]

    addr = parse_listen(url)
    assert addr.host is not None and addr.port is not None
    return adapter_class("tcp-listen")(addr.host, addr.port, timeout=timeout)  # type: ignore[call-arg]
