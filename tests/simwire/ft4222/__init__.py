"""A simulated ``ft4222`` over the test wire of ``simwire`` (tests only; no hardware).

It offers the part of the real package's API the product uses, with the real signatures
(``tests/test_phy_simwire_api.py`` checks it against the installed package and its stubs). A
chip is a master or a slave (raw mode: a byte stream without chip-select edges, as the FT4222H
delivers it) on the wire ``links`` of ``wire.json`` say.
"""

from __future__ import annotations

import enum
from typing import Any

import simwire

from . import SPI, SPIMaster, SPISlave

__all__ = ["SPI", "SPIMaster", "SPISlave"]


class FT2XXDeviceError(Exception):
    def __init__(self, msgnum: int) -> None:
        super().__init__(f"FT2XX error {msgnum}")
        self.msgnum = msgnum


class FT4222DeviceError(FT2XXDeviceError):
    pass


DEVICE_NOT_FOUND = 2
DEVICE_NOT_OPENED = 3


class SysClock(enum.IntEnum):
    CLK_60 = 0
    CLK_24 = 1
    CLK_48 = 2
    CLK_80 = 3


def createDeviceInfoList() -> int:
    return len(simwire.config().get("ft4222", []))


def getDeviceInfoDetail(devnum: int, update: bool = True) -> dict[str, Any]:
    serials = simwire.config().get("ft4222", [])
    if not 0 <= devnum < len(serials):
        raise FT2XXDeviceError(DEVICE_NOT_FOUND)
    return {"index": devnum, "flags": 0, "type": 10, "id": 0x04036011, "location": devnum,
            "serial": serials[devnum].encode(), "description": b"FT4222 A", "handle": 0}


def openBySerial(serial: str | bytes) -> FT4222:
    name = serial.decode() if isinstance(serial, bytes) else serial
    if name not in simwire.config().get("ft4222", []):
        raise FT2XXDeviceError(DEVICE_NOT_FOUND)
    return FT4222(name)


class FT4222:
    def __init__(self, name: str) -> None:
        self._name = name
        self._sender: simwire.Sender | None = None
        self._endpoint: simwire.Endpoint | None = None
        self._mode = 0
        self._stream = bytearray()
        self._check()

    def _publish(self) -> None:
        port = self._endpoint.port if self._endpoint is not None else None
        simwire.publish(self._name, self._mode, False, port)

    def _check(self) -> None:
        if self._name is None or simwire.unplugged(self._name):
            raise FT4222DeviceError(DEVICE_NOT_OPENED)

    def setClock(self, clk: SysClock) -> None:
        self._check()

    def spiMaster_Init(self, mode: SPIMaster.Mode, clock: SPIMaster.Clock, cpol: SPI.Cpol,
                       cpha: SPI.Cpha, ssoMap: SPIMaster.SlaveSelect) -> None:
        self._check()
        self._mode = int(cpol) * 2 + int(cpha)
        self._sender = simwire.Sender(self._name)
        self._publish()

    def spiMaster_SingleWrite(self, data: int | bytes | bytearray,
                              isEndTransaction: bool) -> int:
        self._check()
        if self._sender is None:
            raise FT4222DeviceError(DEVICE_NOT_OPENED)
        payload = bytes([data]) if isinstance(data, int) else bytes(data)
        self._sender.transfer(payload, self._mode, False)
        return len(payload)

    def spiSlave_InitEx(self, proto: SPISlave.Protocol) -> None:
        self._check()
        self._endpoint = simwire.Endpoint(self._name)
        self._endpoint.sock.setblocking(False)
        self._publish()

    def spiSlave_SetMode(self, cpol: SPI.Cpol, cpha: SPI.Cpha) -> None:
        self._check()
        self._mode = int(cpol) * 2 + int(cpha)
        self._publish()

    def spiSlave_GetRxStatus(self) -> int:
        self._check()
        if self._endpoint is None:
            raise FT4222DeviceError(DEVICE_NOT_OPENED)
        while True:
            try:
                self._stream += self._endpoint.sock.recv(65536)
            except (TimeoutError, BlockingIOError):
                return len(self._stream)

    def spiSlave_Read(self, bytesToRead: int) -> bytes:
        self._check()
        out = bytes(self._stream[:bytesToRead])
        del self._stream[:bytesToRead]
        return out

    def close(self) -> None:
        simwire.close(self._endpoint, self._sender)
        self._endpoint = self._sender = None
