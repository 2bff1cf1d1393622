"""The dissector's inputs: :mod:`eyeq_spi.io` reads every capture format (names, suffixes and
detection in its registry); this module keeps the names dissect's callers import."""

from __future__ import annotations

from eyeq_spi.io.plain import (
    _BINARY_LEAD,
    FORMATS,
    LOGIC_FORMATS,
    MAX_HEX_LINE,
    InputError,
    PeekStream,
    _detect,
    detect,
    open_records,
)

__all__ = ["FORMATS", "LOGIC_FORMATS", "MAX_HEX_LINE", "_BINARY_LEAD", "InputError",
           "PeekStream", "_detect", "detect", "open_records"]
