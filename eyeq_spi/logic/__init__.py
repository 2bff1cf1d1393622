"""Logic-analyzer captures of the two SPI channels (seed 004 §5, ``specs/bench.yaml``).

Readers for Saleae Logic 2 and Logic 1.x SPI analyzer exports and for VCD waveforms yield the
dissector's ``Transfer(time, direction, data)``, one per chip-select transfer, streaming in bounded
memory; :mod:`eyeq_spi.logic.vcd_write` turns transfers back into waveforms.
"""
