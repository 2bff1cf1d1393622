"""Whether the link's own counters explain a failed bring-up: a bad link is not a bad camera.

A clean link corrupts no frame (a bit error rate of 1e-9 hits one 128-byte frame in about a
million), so :data:`CORRUPT_SHARE` of the frames received arriving corrupt (CRC or format
errors, §9.2), at least :data:`CORRUPT_MIN` of them, names the link as the likely cause."""

from __future__ import annotations

from eyeq_spi.link.counters import SpiDiagnosticInfo

CORRUPT_SHARE = 0.01  # of the frames received, corrupt on arrival
CORRUPT_MIN = 5  # and at least this many: a stray error or two is no pattern
LIKELY = "the SPI link is the likely cause, not the EyeQ"


def link_suspect(counters: SpiDiagnosticInfo) -> str | None:
    """The words that name the link as the likely cause, with its figures; None when its
    counters do not explain a failure."""
    corrupt = counters.dataCRCErrorCounter + counters.formatErrorCounter
    received = counters.framesReceived + corrupt
    if corrupt < CORRUPT_MIN or corrupt < CORRUPT_SHARE * received:
        return None
    naks = sum(counters.naksReceived.values())
    return (f"{LIKELY}: {corrupt} of {received} frames "
            f"received corrupt ({100 * corrupt / received:.0f} %; "
            f"CRC {counters.dataCRCErrorCounter}, "
            f"format {counters.formatErrorCounter}), {naks} of our frames NAKed, "
            f"{counters.sendFailedErrorCounter} messages not ACKed in time (a clean link has none)")


def with_link_cause(problem: str, counters: SpiDiagnosticInfo) -> str:
    """``problem``, followed by the link's figures when they explain it (once: a problem that
    already names the link keeps the figures of the moment it was found)."""
    suspect = link_suspect(counters)
    return problem if suspect is None or LIKELY in problem else f"{problem}; {suspect}"
