"""EventCalibrationTool parameters (decision M5): ``ct_type``, ``ct_stage``, ``ct_version`` and
the init message's bytes, for every init message of the catalogue."""

from __future__ import annotations

from dataclasses import dataclass

from eyeq_spi.catalog.messages import Catalog, InitMessageDef, catalog
from eyeq_spi.codec.bits import BitSignalCodec
from eyeq_spi.errors import LocalProtocolError, SpecError


@dataclass(frozen=True)
class InitMessage:
    definition: InitMessageDef
    codec: BitSignalCodec | None  # None where the seed prints no bit table (0x78 IPB)

    @property
    def ct_type(self) -> int:
        return int(self.definition.ct_type or 3)

    def ct_version(self, params: bytes) -> int:
        """The message's own protocol-version signal (M5), 0 where there is none."""
        if self.codec is None:
            return 0
        for name in self.codec.signals:
            if "protocol" in name.lower() and "ver" in name.lower():
                raw = self.codec.decode_raw(params)[name] if len(params) == self.codec.length \
                    else int(self.codec.signals[name].initial)
                return int(raw) & 0xFF
        return 0

    def check(self, params: bytes) -> list[str]:
        if self.codec is None:
            return []  # no table to check against: accepted as opaque bytes
        return self.codec.check(params)


def init_message(stage: int, sw: str | None = None, cat: Catalog | None = None) -> InitMessage:
    cat = cat or catalog()
    for definition in cat.init_messages.values():
        if definition.id == stage and definition.name != "EEPROM_DATA":
            try:
                codec: BitSignalCodec | None = BitSignalCodec.for_message(definition.name, sw, cat)
            except SpecError:
                if definition.variants:
                    raise
                codec = None
            return InitMessage(definition, codec)
    raise LocalProtocolError(f"no init message with ct_stage 0x{stage:02X}")
