"""Transfers over a byte stream (decision S): COBS-encoded, each followed by one 0x00.

Shared by the pyserial and TCP adapters. Uses the ``cobs`` package.
"""

from __future__ import annotations

from cobs import cobs

from eyeq_spi.phy.base import Adapter

DELIMITER = b"\x00"
MAX_ENCODED = 64 * 1024  # a runaway frame without delimiter is dropped past this size


def encode_transfer(transfer: bytes) -> bytes:
    return bytes(cobs.encode(transfer)) + DELIMITER


class CobsDecoder:
    """Feed stream bytes, get whole transfers. Undecodable chunks are counted and dropped."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.errors = 0

    def feed(self, data: bytes) -> list[bytes]:
        self._buf += data
        out: list[bytes] = []
        while (end := self._buf.find(DELIMITER)) >= 0:
            chunk = bytes(self._buf[:end])
            del self._buf[: end + 1]
            if not chunk:
                continue  # idle delimiters are allowed between frames
            try:
                out.append(bytes(cobs.decode(chunk)))
            except cobs.DecodeError:
                self.errors += 1
        if len(self._buf) > MAX_ENCODED:
            self._buf.clear()
            self.errors += 1
        return out


class StreamAdapter(Adapter):
    """Base for adapters over a byte stream: subclasses provide ``_write`` and ``_read``."""

    def __init__(self) -> None:
        super().__init__()
        self._decoder = CobsDecoder()
        self._ready: list[bytes] = []

    def _send_internal(self, transfer: bytes) -> None:
        self._write(encode_transfer(transfer))

    def _recv_internal(self, timeout: float | None) -> bytes | None:
        if not self._ready:
            data = self._read(timeout)
            if data:
                self._ready.extend(self._decoder.feed(data))
                self.stats.decode_errors = self._decoder.errors
        return self._ready.pop(0) if self._ready else None

    def discard_pending(self) -> int:
        """Drop the transfers received but not yet taken and any partial one (the peer that
        sent them left); returns how many whole transfers were dropped."""
        dropped = len(self._ready)
        self._ready.clear()
        self._decoder = CobsDecoder()
        return dropped

    def _write(self, data: bytes) -> None:
        raise NotImplementedError

    def _read(self, timeout: float | None) -> bytes:
        raise NotImplementedError
