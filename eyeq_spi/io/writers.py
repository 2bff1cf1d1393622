"""Capture writers with the registry's one signature, ``write(transfers, path, **options) ->
transfers written``, over the streaming writers that demo, host, sim and export use."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from eyeq_spi.capture.pcapng_io import CaptureWriter, Transfer


def write_pcapng(transfers: Iterable[Transfer], path: str | Path, *, sw: str | None = None,
                 default_direction: str = "h2e") -> int:
    """A pcapng capture (``specs/capture.yaml``); ``sw`` is recorded as the traffic's release.
    A transfer without a time gets the previous one's; one without a direction goes to
    ``default_direction``."""
    count = 0
    last = 0.0
    with CaptureWriter(path, sw, idle_flush=False) as writer:
        for transfer in transfers:
            last = transfer.time if transfer.time is not None else last
            writer.write(transfer.direction or default_direction, last, transfer.data)
            count += 1
    return count


def write_vcd_file(transfers: Iterable[Transfer], path: str | Path, **options: Any) -> int:
    """SPI waveforms (:class:`eyeq_spi.logic.vcd_write.VcdWriter`; ``options`` are its
    keyword arguments, ``opts`` the SPI options)."""
    from eyeq_spi.logic.vcd_write import write_vcd

    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        writer = write_vcd(transfers, fh, options.pop("opts", None), **options)
    return int(writer.count)
