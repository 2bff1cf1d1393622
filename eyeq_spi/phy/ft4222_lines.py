"""FTDI FT4222H channels (``ft4222://SERIAL_OR_INDEX``), with the ``ft4222`` package.

One chip is one channel (master or slave, never both). The master clocks each transfer with chip
select low for exactly that transfer, at the 80 MHz system clock divided by a power of two. The
slave runs in raw mode (``SPI_SLAVE_NO_PROTOCOL``), which has no chip-select edges: 128 bytes make
a transfer (§6), and bytes followed by ``idle`` seconds of silence a short one. The chip is polled
every ``POLL`` seconds, far inside the 10 ms ackTimeout. It sends most
significant bit first only."""

from __future__ import annotations

import contextlib
import math
import time

from eyeq_spi.errors import AdapterError, MissingExtra
from eyeq_spi.phy.spi import FRAME_LEN, SpiSettings

try:
    import ft4222
    from ft4222 import SPI, SPIMaster, SPISlave

    HAVE_FT4222 = True
except ImportError:  # pragma: no cover - the [bench] extra
    HAVE_FT4222 = False

SYSTEM_CLOCK_HZ = 80_000_000
POLL = 0.0005  # s between two looks at the slave's receive count
IDLE = 0.002  # s of silence that end a short transfer in raw slave mode


def _need() -> None:
    if not HAVE_FT4222:
        raise MissingExtra("bench", "ft4222:// needs the ft4222 package")


def open_chip(target: str) -> ft4222.FT4222:
    """The FT4222H with serial number ``target``, or the ``target``-th FTDI device. Only a
    device the driver lists is opened (``libft4222`` crashes the process on a serial number
    that is not attached)."""
    _need()
    try:
        count = ft4222.createDeviceInfoList()
        serials = [ft4222.getDeviceInfoDetail(i, False)["serial"] for i in range(count)]
    except ft4222.FT2XXDeviceError as exc:
        raise AdapterError(f"cannot open ft4222://{target}: the FTDI driver lists no device "
                           f"({exc}): is an FT4222H attached, and may this user open it?") \
            from exc
    names = [s.decode(errors="replace") if isinstance(s, bytes) else str(s) for s in serials]
    if target.isdigit():
        if int(target) >= count:
            raise AdapterError(f"ft4222://{target}: only {count} FTDI devices attached")
        serial = serials[int(target)]
    elif target in names:
        serial = serials[names.index(target)]
    else:
        raise AdapterError(f"ft4222://{target}: no FTDI device with that serial number "
                           f"(attached: {', '.join(names) or 'none'})")
    try:
        return ft4222.openBySerial(serial)
    except ft4222.FT2XXDeviceError as exc:
        raise AdapterError(f"cannot open ft4222://{target}: {exc}") from exc


def clock_divider(clock_hz: int) -> SPIMaster.Clock:
    """The divider of the 80 MHz system clock giving at most ``clock_hz``."""
    _need()
    exponent = max(1, math.ceil(math.log2(SYSTEM_CLOCK_HZ / clock_hz)))
    if exponent > 9:
        raise AdapterError(f"the FT4222H cannot clock SPI as slow as {clock_hz} Hz")
    return SPIMaster.Clock(exponent)


class _Ft4222Channel:
    lsb_first = False  # the FT4222H sends most significant bit first only

    def __init__(self, target: str) -> None:
        self.name = f"ft4222://{target}"
        self.chip = open_chip(target)

    def close(self) -> None:
        with contextlib.suppress(ft4222.FT2XXDeviceError):
            self.chip.close()


class Ft4222Master(_Ft4222Channel):
    """Our master channel on one FT4222H (chip select SS0)."""

    def __init__(self, target: str, settings: SpiSettings) -> None:
        super().__init__(target)
        try:
            self.chip.setClock(ft4222.SysClock["CLK_80"])
            self.chip.spiMaster_Init(SPIMaster.Mode.SINGLE, clock_divider(settings.clock_hz),
                                     SPI.Cpol(settings.mode >> 1), SPI.Cpha(settings.mode & 1),
                                     SPIMaster.SlaveSelect.SS0)
        except ft4222.FT2XXDeviceError as exc:
            self.close()
            raise AdapterError(f"{self.name}: cannot set up the SPI master: {exc}") from exc

    def write(self, transfer: bytes) -> None:
        try:
            self.chip.spiMaster_SingleWrite(transfer, True)
        except ft4222.FT2XXDeviceError as exc:
            raise AdapterError(f"{self.name}: write failed: {exc}") from exc


class Ft4222Slave(_Ft4222Channel):
    """Our slave channel on one FT4222H in raw slave mode (see the module doc). The chip does
    not report lost bytes: a transfer cut by an overrun reaches the link short (counted, L8)."""

    def __init__(self, target: str, settings: SpiSettings, *, idle: float = IDLE) -> None:
        self.idle = idle
        self.overruns = 0
        self._bytes = bytearray()
        super().__init__(target)
        try:
            self.chip.spiSlave_InitEx(SPISlave.Protocol.SPI_SLAVE_NO_PROTOCOL)
            self.chip.spiSlave_SetMode(SPI.Cpol(settings.mode >> 1), SPI.Cpha(settings.mode & 1))
        except ft4222.FT2XXDeviceError as exc:
            self.close()
            raise AdapterError(f"{self.name}: cannot set up the SPI slave: {exc}") from exc

    def read(self, timeout: float) -> bytes | None:
        end = time.monotonic() + timeout
        last = time.monotonic()
        while True:
            if len(self._bytes) >= FRAME_LEN:
                return self._take(FRAME_LEN)
            try:
                waiting = self.chip.spiSlave_GetRxStatus()
                if waiting:
                    self._bytes += self.chip.spiSlave_Read(waiting)
                    last = time.monotonic()
                    continue
            except ft4222.FT2XXDeviceError as exc:
                raise AdapterError(f"{self.name}: read failed: {exc}") from exc
            now = time.monotonic()
            if self._bytes and now - last >= self.idle:
                return self._take(len(self._bytes))  # chip select rose early
            if not self._bytes and now >= end:
                return None
            time.sleep(POLL)

    def _take(self, count: int) -> bytes:
        out = bytes(self._bytes[:count])
        del self._bytes[:count]
        return out
