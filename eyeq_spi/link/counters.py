"""Link counters: the seed's ``eyeq_spi_diagnostic_info_t`` (§9.2) under its member names, plus
finer counts that the seed does not name (kept apart so that the §9.2 view stays exact)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields


@dataclass
class SpiDiagnosticInfo:
    # §9.2 eyeq_spi_diagnostic_info_t
    sequenceErrorCounter: int = 0  # NAK 0x001 sent
    dataCRCErrorCounter: int = 0  # NAK 0x002 sent, or a broken ACK/NAK
    formatErrorCounter: int = 0  # NAK 0x011 sent, or a transfer of the wrong length (L8)
    sendFailedErrorCounter: int = 0  # application messages that failed (L7)
    fifoNonEmptyCounter: int = 0  # a DATA frame had to wait because W frames were in transit
    busyFrames: int = 0  # frames currently in transit (gauge)
    rcvOverflowErrors: int = 0  # multi-frame `total` above the receive limit (T6)
    # beyond §9.2
    badLengthTransfers: int = 0
    duplicateFrames: int = 0
    skippedFrames: int = 0
    lateFrames: int = 0  # L6a: a NUM in [E-W, E) that was skipped, NAKed 0x001
    resynchronisations: int = 0  # L6/L6a: E taken from a frame after NAKs or a peer reset
    framesReceived: int = 0
    framesAcked: int = 0
    unexpectedAckCounter: int = 0
    naksSent: dict[int, int] = field(default_factory=dict)
    naksReceived: dict[int, int] = field(default_factory=dict)

    def seed_view(self) -> dict[str, int]:
        """The §9.2 structure (the first seven fields), as EYEQ_BASE_DIAG_STATUS_MSG (0xA0) would
        send it."""
        return {name: int(getattr(self, name)) & 0xFFFFFFFF for name in SEED_COUNTERS}


SEED_COUNTERS = tuple(member.name for member in fields(SpiDiagnosticInfo))[:7]  # §9.2
