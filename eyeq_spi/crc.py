"""CRC-16 of the link layer (decision L3) and of E2E-protected signals (decision D5).

The CRC must run at C speed. ``binascii.crc_hqx`` is CRC-16/XMODEM in C; seeded with 0xFFFF it is
exactly CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, xorout 0). crcmod is the
general engine for the other variants a device might use; its C extension is checked so that a
silent pure-Python fallback is reported.
"""

from __future__ import annotations

import binascii
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from eyeq_spi.errors import UsageError

CrcFunction = Callable[[bytes], int]


@dataclass(frozen=True)
class CrcVariant:
    """A CRC-16 definition in the Rocksoft/catalogue terms."""

    name: str
    poly: int
    init: int
    reflect: bool
    xorout: int
    check: int


CCITT_FALSE = CrcVariant("CRC-16/CCITT-FALSE", 0x1021, 0xFFFF, False, 0x0000, 0x29B1)
# Other variants a device could plausibly use; kept here so a configuration can name them.
VARIANTS: dict[str, CrcVariant] = {
    v.name: v
    for v in (
        CCITT_FALSE,
        CrcVariant("CRC-16/XMODEM", 0x1021, 0x0000, False, 0x0000, 0x31C3),
        CrcVariant("CRC-16/KERMIT", 0x1021, 0x0000, True, 0x0000, 0x2189),
        CrcVariant("CRC-16/GENIBUS", 0x1021, 0xFFFF, False, 0xFFFF, 0xD64E),
    )
}


def crcmod_uses_c_extension() -> bool:
    """True if crcmod runs its C extension (``crcmod._crcfunext``)."""
    import crcmod.crcmod  # here: the default CRC (binascii) never needs it

    # crcmod.crcmod imports ``crcmod._crcfunext`` when it can and silently falls back otherwise.
    return getattr(crcmod.crcmod, "_crcfunext", None) is not None


def _crc_hqx_ccitt_false(data: bytes) -> int:
    return binascii.crc_hqx(data, 0xFFFF)


def make_crc(variant: CrcVariant = CCITT_FALSE, *, engine: str = "auto") -> CrcFunction:
    """A ``bytes -> int`` CRC function for ``variant``; ``engine`` is ``"binascii"``
    (CCITT-FALSE only), ``"crcmod"`` or ``"auto"`` (binascii where it applies, else crcmod).
    Asking for crcmod without its C extension warns."""
    if engine not in ("auto", "binascii", "crcmod"):
        raise UsageError(f"unknown CRC engine {engine!r}")
    hqx_ok = (variant.poly, variant.init, variant.reflect, variant.xorout) == (
        0x1021, 0xFFFF, False, 0,
    )
    if engine == "binascii" and not hqx_ok:
        raise UsageError(f"binascii.crc_hqx cannot compute {variant.name}")
    if engine in ("auto", "binascii") and hqx_ok:
        return _crc_hqx_ccitt_false
    if not crcmod_uses_c_extension():
        warnings.warn(
            "crcmod is running without its C extension: CRC throughput will be poor",
            RuntimeWarning,
            stacklevel=2,
        )
    import crcmod

    fn: Any = crcmod.mkCrcFun(
        0x10000 | variant.poly,
        # crcmod wants the initial register XORed with xorOut (its documented convention).
        initCrc=variant.init ^ variant.xorout,
        rev=variant.reflect,
        xorOut=variant.xorout,
    )
    if fn(b"123456789") != variant.check:
        raise UsageError(f"crcmod set-up for {variant.name} fails its check value")
    return fn  # type: ignore[no-any-return]


crc16 = _crc_hqx_ccitt_false
"""The default CRC (L3, D5, I2)."""
