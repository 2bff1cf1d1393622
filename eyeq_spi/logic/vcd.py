"""VCD waveforms of SPI lines: the reader the rest of the code imports.

``read_vcd`` is the numpy twin of :mod:`eyeq_spi.logic.vcd_fast` (the reference's token loop
reads any chunk it declines), or with ``EYEQ_SPI_EXACT=1`` the token loop of
:mod:`eyeq_spi.logic.vcd_ref` alone.
"""

from __future__ import annotations

from collections.abc import Iterator

from eyeq_spi.capture.pcapng_io import Record
from eyeq_spi.logic.options import SpiOptions
from eyeq_spi.logic.saleae_types import ByteSource
from eyeq_spi.logic.vcd_ref import sniff
from eyeq_spi.twins import references_only

__all__ = ["read_vcd", "sniff"]


def read_vcd(src: ByteSource, opts: SpiOptions, *, chunk_size: int = 1 << 20
             ) -> Iterator[Record]:
    """Value changes -> one record per transfer and direction."""
    from eyeq_spi.logic import vcd_fast, vcd_ref  # numpy only when a file is read

    if references_only():
        return vcd_ref.read_vcd(src, opts, chunk_size=chunk_size)
    return vcd_fast.read_vcd(src, opts, chunk_size=chunk_size)
