"""The former name of :mod:`eyeq_spi.dissect.engine_fast_frames` (its frame arrays), kept so
that code importing it still runs."""

from eyeq_spi.dissect.engine_fast_frames import (
    BLOCK_ROWS,
    TYPE_NAMES,
    BatchUnsupportedError,
    FrameArrays,
    FrameBlock,
    batch_crc,
    crc_table,
    frame_arrays,
    validate,
)

__all__ = [
    "BLOCK_ROWS",
    "TYPE_NAMES",
    "BatchUnsupportedError",
    "FrameArrays",
    "FrameBlock",
    "batch_crc",
    "crc_table",
    "frame_arrays",
    "validate",
]
