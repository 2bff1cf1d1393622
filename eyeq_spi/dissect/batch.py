"""The former name of :mod:`eyeq_spi.dissect.engine_fast` (the batch dissector), kept so
that code importing it still runs."""

from eyeq_spi.dissect.engine_fast import (
    MIN_SPAN,
    REASSEMBLY_TIMEOUT,
    RECEIVE_LIMIT,
    BatchDissector,
    W,
    iter_items,
    iter_records,
)

__all__ = [
    "MIN_SPAN",
    "REASSEMBLY_TIMEOUT",
    "RECEIVE_LIMIT",
    "BatchDissector",
    "W",
    "iter_items",
    "iter_records",
]
