"""Saleae SPI analyzer exports: the readers the rest of the code imports.

``read_saleae2``/``read_saleae1`` are the numpy twins of :mod:`eyeq_spi.logic.saleae_fast`
(the reference's csv loop reads any chunk they decline), or with ``EYEQ_SPI_EXACT=1`` the
reference of :mod:`eyeq_spi.logic.saleae_ref` alone.
"""

from __future__ import annotations

from collections.abc import Iterator

from eyeq_spi.capture.pcapng_io import Record
from eyeq_spi.logic.options import SpiOptions
from eyeq_spi.logic.saleae_ref import sniff
from eyeq_spi.logic.saleae_types import ByteSource
from eyeq_spi.twins import references_only

__all__ = ["ByteSource", "read_saleae1", "read_saleae2", "sniff"]


def read_saleae2(src: ByteSource, opts: SpiOptions, *, chunk_size: int = 1 << 20
                 ) -> Iterator[Record]:
    """Logic 2 "Export table" rows -> one record per transfer and direction."""
    from eyeq_spi.logic import saleae_fast, saleae_ref  # numpy only when a file is read

    if references_only():
        return saleae_ref.read_saleae2(src, opts, chunk_size=chunk_size)
    return saleae_fast.read_saleae2(src, opts, chunk_size=chunk_size)


def read_saleae1(src: ByteSource, opts: SpiOptions, *, chunk_size: int = 1 << 20
                 ) -> Iterator[Record]:
    """Logic 1.x rows (one Packet ID per transfer) -> one record per transfer and direction."""
    from eyeq_spi.logic import saleae_fast, saleae_ref

    if references_only():
        return saleae_ref.read_saleae1(src, opts, chunk_size=chunk_size)
    return saleae_fast.read_saleae1(src, opts, chunk_size=chunk_size)
