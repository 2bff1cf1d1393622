"""The former name of :mod:`eyeq_spi.capture.pcapng_fast` (the array reader of captures),
kept so that code importing it still runs."""

from eyeq_spi.capture.pcapng_fast import (
    CHUNK,
    DIR_CODE,
    DIR_NAME,
    Chunk,
    chunks_from_records,
    pcapng_chunks,
    raw_chunks,
)

__all__ = ["CHUNK", "DIR_CODE", "DIR_NAME", "Chunk", "chunks_from_records", "pcapng_chunks",
           "raw_chunks"]
