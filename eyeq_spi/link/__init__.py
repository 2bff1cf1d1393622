"""Link layer (seed 004 §6): frames, CRC, ACK/NAK, window, timers. Sans-IO."""

from eyeq_spi.link.connection import LinkConfig, LinkConnection, Role
from eyeq_spi.link.counters import SpiDiagnosticInfo
from eyeq_spi.link.frame import FRAME_SIZE, BitOrder, Frame, FrameCodec, FrameKind, NakReason

__all__ = [
    "FRAME_SIZE", "BitOrder", "Frame", "FrameCodec", "FrameKind", "LinkConfig", "LinkConnection",
    "NakReason", "Role", "SpiDiagnosticInfo",
]
