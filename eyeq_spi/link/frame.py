"""Link frame codec (seed 004 §6, decisions L1-L3): a uint32 LE header word (D/R/RSP/NUM, bit
positions from ``specs/link.yaml``), a CRC-16 LE and 122 data bytes; ``FRAME_LAYOUT`` is the
byte layout as a construct Struct, the reference the codec is tested against."""

from __future__ import annotations

import binascii
import enum
from dataclasses import dataclass
from typing import Any

from eyeq_spi.catalog.link import link_spec
from eyeq_spi.crc import CCITT_FALSE, CrcFunction, CrcVariant, make_crc
from eyeq_spi.errors import LocalProtocolError, RemoteProtocolError

_SPEC = link_spec()
FRAME_SIZE: int = _SPEC["frame"]["size"]
DATA_SIZE: int = _SPEC["frame"]["data_size"]
SEQ_MODULO: int = _SPEC["sequence"]["modulo"]


class FrameKind(enum.IntEnum):
    """Values of the D field (L2)."""

    DATA = _SPEC["kinds"]["DATA"]
    ACK = _SPEC["kinds"]["ACK"]
    NAK = _SPEC["kinds"]["NAK"]


class NakReason(enum.IntEnum):
    """NAK reasons (L5), carried in the NUM field of a NAK."""

    OUT_OF_WINDOW = 0x001
    CRC_MISMATCH = 0x002
    FORMAT_ERROR = 0x011


class BitOrder(enum.Enum):
    LSB_FIRST = "lsb_first"
    MSB_FIRST = "msb_first"


def __getattr__(name: str) -> Any:
    """``FRAME_LAYOUT``, built on first use so that no reader imports construct."""
    if name == "FRAME_LAYOUT":
        from construct import Bytes, Int16ul, Int32ul, Struct

        layout = Struct(
            "header" / Int32ul,
            "crc" / Int16ul,
            "data" / Bytes(DATA_SIZE),
        ).compile()
        globals()["FRAME_LAYOUT"] = layout
        return layout
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _field_shifts(order: BitOrder) -> dict[str, tuple[int, int]]:
    """name -> (shift, mask) for the header fields, in the seed's table order."""
    fields = [(str(n), int(w)) for n, w in _SPEC["frame"]["header"]["fields"]]
    if order is BitOrder.MSB_FIRST:
        fields = fields[::-1]
    out: dict[str, tuple[int, int]] = {}
    pos = 0
    for name, width in fields:
        out[name] = (pos, (1 << width) - 1)
        pos += width
    return out


@dataclass(frozen=True, slots=True)
class Frame:
    """A decoded frame. ``d`` is kept as an int so that invalid kinds can be represented."""

    d: int
    r: int
    rsp: int
    num: int
    data: bytes = bytes(DATA_SIZE)
    crc: int = 0

    def __post_init__(self) -> None:
        if not (0 <= self.d <= 0xF and 0 <= self.r <= 0xF):
            raise LocalProtocolError(f"D/R out of 4-bit range: {self.d}, {self.r}")
        if not (0 <= self.rsp < SEQ_MODULO and 0 <= self.num < SEQ_MODULO):
            raise LocalProtocolError(f"RSP/NUM out of 12-bit range: {self.rsp}, {self.num}")
        if len(self.data) != DATA_SIZE:
            raise LocalProtocolError(f"frame data must be {DATA_SIZE} bytes, got {len(self.data)}")

    @property
    def kind(self) -> FrameKind | None:
        try:
            return FrameKind(self.d)
        except ValueError:
            return None


_ZERO_DATA = bytes(DATA_SIZE)


class FrameCodec:
    """Encode and decode frames for one configuration (CRC variant, header bit order)."""

    def __init__(
        self,
        *,
        crc: CrcVariant | CrcFunction = CCITT_FALSE,
        bit_order: BitOrder | str = _SPEC["frame"]["header"]["bit_order"],
    ) -> None:
        self.crc: CrcFunction = make_crc(crc) if isinstance(crc, CrcVariant) else crc
        self.bit_order = BitOrder(bit_order)
        shifts = _field_shifts(self.bit_order)
        self._d, self._r = shifts["D"], shifts["R"]
        self._rsp, self._num = shifts["RSP"], shifts["NUM"]
        self._acks: dict[int, bytes] = {}  # NUM -> ACK frame: built once (hot path)
        self._data_word = int(FrameKind.DATA) << self._d[0]
        self._hqx = self.crc is make_crc(CCITT_FALSE)  # binascii.crc_hqx seeded 0xFFFF (L3)

    def pack_header(self, d: int, r: int, rsp: int, num: int) -> int:
        return (
            (d << self._d[0]) | (r << self._r[0]) | (rsp << self._rsp[0]) | (num << self._num[0])
        )

    def unpack_header(self, word: int) -> tuple[int, int, int, int]:
        return (
            (word >> self._d[0]) & self._d[1],
            (word >> self._r[0]) & self._r[1],
            (word >> self._rsp[0]) & self._rsp[1],
            (word >> self._num[0]) & self._num[1],
        )

    # L3: DATA frames cover header and data, ACK/NAK the header only
    def compute_crc(self, d: int, header: bytes, data: bytes) -> int:
        if d in (FrameKind.ACK, FrameKind.NAK):
            return self.crc(header)
        return self.crc(header + data)

    def encode(self, frame: Frame) -> bytes:
        word = self.pack_header(frame.d, frame.r, frame.rsp, frame.num)
        header = word.to_bytes(4, "little")
        data = frame.data if frame.d not in (FrameKind.ACK, FrameKind.NAK) else _ZERO_DATA
        crc = self.compute_crc(frame.d, header, data)
        return header + crc.to_bytes(2, "little") + data

    def data_frame(self, rsp: int, num: int, data: bytes) -> bytes:
        """``encode(Frame(DATA, 0, rsp, num, data))`` without building the Frame (every frame a
        sender releases), ``data`` zero-padded to 122 bytes (§6 pad bytes)."""
        if len(data) > DATA_SIZE:
            raise LocalProtocolError(f"data field holds {DATA_SIZE} bytes, got {len(data)}")
        if not (0 <= rsp < SEQ_MODULO and 0 <= num < SEQ_MODULO):
            raise LocalProtocolError(f"RSP/NUM out of 12-bit range: {rsp}, {num}")
        header = (self._data_word | (rsp << self._rsp[0]) | (num << self._num[0])).to_bytes(
            4, "little")
        data = data.ljust(DATA_SIZE, b"\0")
        if self._hqx:  # CCITT-FALSE (L3): crc_hqx chained over header and data, nothing joined
            crc = binascii.crc_hqx(data, binascii.crc_hqx(header, 0xFFFF))
        else:
            crc = self.crc(header + data)
        return header + crc.to_bytes(2, "little") + data

    def ack(self, num: int) -> bytes:
        """L5: an ACK's RSP is the accepted frame's NUM, its NUM is 0."""
        frame = self._acks.get(num)
        if frame is None:
            frame = self._acks[num] = self.encode(Frame(FrameKind.ACK, 0, num, 0))
        return frame

    def nak(self, num: int, reason: NakReason) -> bytes:
        """L5: a NAK's RSP is the rejected frame's NUM, its NUM holds the reason."""
        return self.encode(Frame(FrameKind.NAK, 0, num, int(reason)))

    def decode(self, transfer: bytes) -> Frame:
        """The frame with the CRC found in it, unjudged (:meth:`crc_ok`); ``RemoteProtocolError``
        for a wrong length (L8)."""
        if len(transfer) != FRAME_SIZE:
            raise RemoteProtocolError(f"transfer is {len(transfer)} bytes, not {FRAME_SIZE}")
        d, r, rsp, num = self.unpack_header(int.from_bytes(transfer[:4], "little"))
        return Frame(d, r, rsp, num, bytes(transfer[6:]),
                     int.from_bytes(transfer[4:6], "little"))

    def check(self, transfer: bytes) -> tuple[int, int, int, int, bool]:
        """D, R, RSP, NUM and the CRC verdict: :meth:`decode` and :meth:`crc_ok` without a
        :class:`Frame` (the receiver's hot path)."""
        if len(transfer) != FRAME_SIZE:
            raise RemoteProtocolError(f"transfer is {len(transfer)} bytes, not {FRAME_SIZE}")
        word = int.from_bytes(transfer[:4], "little")
        d = (word >> self._d[0]) & self._d[1]
        crc = int.from_bytes(transfer[4:6], "little")
        if d == FrameKind.ACK or d == FrameKind.NAK:
            ok = self.crc(transfer[:4]) == crc
        else:
            ok = self.crc(transfer[:4] + transfer[6:]) == crc
        return (d, (word >> self._r[0]) & self._r[1], (word >> self._rsp[0]) & self._rsp[1],
                (word >> self._num[0]) & self._num[1], ok)

    def crc_ok(self, transfer: bytes, frame: Frame) -> bool:
        return self.compute_crc(frame.d, transfer[:4], transfer[6:]) == frame.crc
