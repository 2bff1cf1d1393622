"""The former name of :mod:`eyeq_spi.dissect.engine_fast_messages` (its span messages), kept so
that code importing it still runs."""

from eyeq_spi.dissect.engine_fast_messages import (
    FIELD_MODES,
    LEAN_MODES,
    ColumnGroup,
    GroupCount,
    SpanDecoder,
    SpanMessage,
)

__all__ = [
    "FIELD_MODES",
    "LEAN_MODES",
    "ColumnGroup",
    "GroupCount",
    "SpanDecoder",
    "SpanMessage",
]
