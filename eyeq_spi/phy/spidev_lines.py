"""Linux spidev channels (``spidev:///dev/spidevB.C``), with the ``spidev`` package.

A master channel writes each transfer with ``writebytes2`` (chip select low for all of it); a
slave channel (the Linux SPI slave framework) reads with ``read(2)``, since ``readbytes`` refuses a
short read and a short transfer must reach the link as short (decision L8)."""

from __future__ import annotations

import contextlib
import os
import select

from eyeq_spi.errors import AdapterError, MissingExtra
from eyeq_spi.phy.spi import FRAME_LEN, SpiSettings

try:
    import spidev

    HAVE_SPIDEV = True
except ImportError:  # pragma: no cover - the [bench] extra
    HAVE_SPIDEV = False


def _open(path: str, settings: SpiSettings) -> tuple[spidev.SpiDev, bool]:
    """The device at ``path`` in the settings' mode and clock; whether the controller itself
    sends least significant bit first (when asked for and it can)."""
    if not HAVE_SPIDEV:
        raise MissingExtra("bench", "spidev:// needs the spidev package")
    dev = spidev.SpiDev()
    try:
        dev.open_path(path)
        dev.mode = settings.mode
        dev.max_speed_hz = settings.clock_hz
        dev.bits_per_word = 8
    except (OSError, ValueError, TypeError) as exc:
        with contextlib.suppress(OSError):
            dev.close()
        raise AdapterError(f"cannot open {path} as SPI mode {settings.mode} at "
                           f"{settings.clock_hz} Hz: {exc}") from exc
    lsb_first = False
    if settings.bit_order == "lsb_first":
        try:
            dev.lsbfirst = True
            lsb_first = True
        except OSError:
            pass  # the controller cannot: the adapter reverses the bits by table
    return dev, lsb_first


class SpidevChannel:
    """Our master channel (``write``) or slave channel (``read``, on a controller in SPI slave
    mode) on ``path``. The slave framework does not report a transfer lost while no read was
    pending, so ``overruns`` stays 0 here; the adapter counts its own."""

    def __init__(self, path: str, settings: SpiSettings) -> None:
        self.name = f"spidev://{path}"
        self.dev, self.lsb_first = _open(path, settings)
        self.overruns = 0

    def write(self, transfer: bytes) -> None:
        try:
            self.dev.writebytes2(transfer)
        except (OSError, SystemError) as exc:  # SystemError: spidev's short write
            raise AdapterError(f"{self.name}: write failed: {exc}") from exc

    def read(self, timeout: float) -> bytes | None:
        try:
            fd = self.dev.fileno()
            ready, _, _ = select.select([fd], [], [], timeout)
            if not ready:
                return None
            data = os.read(fd, FRAME_LEN)
        except (OSError, ValueError) as exc:
            raise AdapterError(f"{self.name}: read failed: {exc}") from exc
        if not data:
            raise AdapterError(f"{self.name}: the device went away")
        return data

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.dev.close()
