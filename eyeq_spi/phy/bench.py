"""Naming one side of a link on SPI lines (seed 004 §5): ``MASTER_URL,SLAVE_URL`` or a bench file.

A ``bench.toml`` (read with :mod:`tomllib`, format in docs/bench.md) names the ``[master]`` and
``[slave]`` URLs and optionally the ``[spi]`` settings (defaults: ``specs/bench.yaml`` and
``specs/link.yaml``: §6 baudRate, §6 E_CADS4_SPI_POLARITY_0_PHASE_1). Every key is checked; a
wrong one is an :class:`~eyeq_spi.errors.UsageError` naming the file."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from eyeq_spi.catalog.link import spec_file
from eyeq_spi.errors import AdapterError, UsageError
from eyeq_spi.phy.address import SPI_FORMS, SPI_SCHEMES
from eyeq_spi.phy.spi import SpiAdapter, SpiSettings

_SPI_KEYS: dict[str, type | tuple[type, ...]] = {
    "clock_hz": int, "mode": int, "bit_order": str, "gap_us": (int, float), "queue": int,
    "silence_ms": (int, float),
}


def default_settings() -> SpiSettings:
    spi = spec_file("bench.yaml")["spi"]
    return SpiSettings(clock_hz=int(spi["baud_rate"]), mode=int(spi["mode"]),
                       bit_order=str(spi["bit_order"]))


@dataclass(frozen=True)
class Side:
    """Where our two channels are, and how they drive the lines."""

    master: str
    slave: str
    settings: SpiSettings

    @property
    def name(self) -> str:
        return f"{self.master},{self.slave}"


def _channel_url(text: str, role: str, where: str) -> str:
    scheme = text.split("://", 1)[0].lower() if "://" in text else ""
    if scheme not in SPI_SCHEMES or not text.split("://", 1)[1]:
        raise UsageError(f"{where}: the {role} channel {text!r} is not spidev:///dev/spidevB.C "
                         f"or ft4222://SERIAL_OR_INDEX")
    return text


def _settings(table: Any, where: str) -> SpiSettings:
    if not isinstance(table, dict):
        raise UsageError(f"{where}: [spi] must be a table")
    unknown = sorted(set(table) - set(_SPI_KEYS))
    if unknown:
        raise UsageError(f"{where}: unknown [spi] key {unknown[0]!r} (known: "
                         f"{', '.join(sorted(_SPI_KEYS))})")
    for key, value in table.items():
        if not isinstance(value, _SPI_KEYS[key]) or isinstance(value, bool):
            raise UsageError(f"{where}: [spi] {key} = {value!r} has the wrong type")
    base = default_settings()
    try:
        return SpiSettings(clock_hz=table.get("clock_hz", base.clock_hz),
                           mode=table.get("mode", base.mode),
                           bit_order=table.get("bit_order", base.bit_order),
                           gap=float(table.get("gap_us", 0)) / 1e6,
                           queue=table.get("queue", base.queue),
                           silence=float(table.get("silence_ms", base.silence * 1e3)) / 1e3)
    except AdapterError as exc:
        raise UsageError(f"{where}: [spi] {exc}") from None


def read_bench(path: str) -> Side:
    """The side a bench file names."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise UsageError(f"no bench file {path}") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise UsageError(f"cannot read bench file {path}: {exc}") from None
    unknown = sorted(set(data) - {"master", "slave", "spi"})
    if unknown:
        raise UsageError(f"{path}: unknown table [{unknown[0]}] (known: master, slave, spi)")
    urls = []
    for role in ("master", "slave"):
        table = data.get(role)
        if not isinstance(table, dict) or not isinstance(table.get("url"), str):
            raise UsageError(f"{path}: [{role}] url = \"...\" is missing")
        if set(table) - {"url"}:
            raise UsageError(f"{path}: [{role}] takes only url")
        urls.append(_channel_url(table["url"], role, path))
    return Side(urls[0], urls[1], _settings(data.get("spi", {}), path))


def parse_side(text: str) -> Side:
    """A URL pair or a bench file (see the module doc)."""
    if text.endswith(".toml"):
        return read_bench(text)
    parts = text.split(",")
    if len(parts) != 2:
        raise UsageError(f"{text!r}: one side on SPI lines is two channels: {SPI_FORMS}")
    return Side(_channel_url(parts[0], "master", text), _channel_url(parts[1], "slave", text),
                default_settings())


def _open_channel(url: str, role: str, settings: SpiSettings) -> Any:
    scheme, target = url.split("://", 1)
    if scheme.lower() == "spidev":
        from eyeq_spi.phy import spidev_lines

        return spidev_lines.SpidevChannel(target, settings)
    from eyeq_spi.phy import ft4222_lines

    return (ft4222_lines.Ft4222Master if role == "master"
            else ft4222_lines.Ft4222Slave)(target, settings)


class BenchAdapter(SpiAdapter):
    """The registry's ``spi`` adapter: both channels of one side, named as :func:`parse_side`
    reads them (or given as a :class:`Side`)."""

    def __init__(self, side: Side | str) -> None:
        if isinstance(side, str):
            side = parse_side(side)
        master = _open_channel(side.master, "master", side.settings)
        try:
            slave = _open_channel(side.slave, "slave", side.settings)
        except BaseException:
            master.close()
            raise
        super().__init__(master, slave, side.settings, name=side.name)
