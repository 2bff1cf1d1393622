"""HOST_VEH_STATE_MSG packed from a template: the fast twin of the reference.

The reference (``VehicleStateSender.encode`` with ``EYEQ_SPI_EXACT=1``) fills a
fresh ``zero_values()`` dict with :func:`~eyeq_spi.host.scenario.veh_state_values` at every
period (§7.1.2.2: 66.67 Hz) and encodes the whole message. Most of it never changes: every
validity flag but the OBS ones, our API version, the sync flag. :class:`VehStatePacker` encodes
that constant part once, with the reference's own encoder, and per message writes only what
changes into a copy: the scenario's signals, the time stamps and ``SPI_Rolling_Count``, each
with the ``struct`` format of its leaf (from the layout, hence from ``specs/``); then the
rolling counter and CRC (D5) with the generated protector
(:func:`~eyeq_spi.codec.e2e.compile_protector`) and the §7.1.2 header, as
``MessageCodec.encode_dasp`` does.

Whatever the template cannot say for certain it leaves to the reference: a signal that is a
bitfield (an OBS validity flag), an array or a struct, or a value its leaf's format refuses
(wrong type, out of range). :meth:`VehStatePacker.encode` then returns None having changed
nothing, and the caller runs the reference, which encodes it or reports the problem as it
always has. ``tests/test_host_veh_state_fast.py`` holds both to the same bytes.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from typing import Any

from eyeq_spi.codec.e2e import E2EState, compile_protector
from eyeq_spi.codec.layout import Layout
from eyeq_spi.codec.layout_fast import FMT
from eyeq_spi.codec.message import DASP_PROTOCOL, MessageCodec
from eyeq_spi.host.scenario import veh_state_values

NAME = "HOST_VEH_STATE_MSG"
_SKIP = None  # a signal the reference overwrites before it encodes: never packed
_REFERENCE = False  # a signal the template cannot pack: the reference encodes the message
_Slot = tuple[struct.Struct, int] | None | bool


def _scalar(lay: Layout, name: str, base: int = 0) -> tuple[struct.Struct, int] | None:
    """The format and absolute offset of a plain (not bitfield, not array) primitive leaf."""
    f = lay.find_field(name)
    if f is None or f.bits is not None or f.count or f.name in lay.children \
            or f.type not in FMT:
        return None
    return struct.Struct("<" + FMT[f.type]), base + f.offset


class VehStatePacker:
    """HOST_VEH_STATE_MSG of one codec's SW release from a constant template."""

    def __init__(self, codec: MessageCodec, api: tuple[int, int]) -> None:
        msg = codec.message(NAME)
        lay = codec.layout(msg)
        self._template = lay.build(veh_state_values(lay.zero_values(), {}, 0.0, api, 0))
        self._head = bytes((DASP_PROTOCOL, msg.data_id))
        self._protect = compile_protector(lay)
        vs_field = lay.field("vehStateInfo")
        vs = lay.children["vehStateInfo"]
        # what veh_state_values writes after the signals, over them: never a signal's value
        members = [f.name for f in vs.fields]
        overwritten = {k for k in members if k.endswith("Validity") and not k.startswith("OBS")}
        overwritten |= {"timestamp_us", "apiVersionMajor", "apiVersionMinor"}
        self._signals: dict[str, _Slot] = {
            k: _SKIP if k in overwritten else (_scalar(vs, k, vs_field.offset) or _REFERENCE)
            for k in members}
        stamps = [_scalar(vs, "timestamp_us", vs_field.offset),
                  _scalar(lay, "host_sync_timestamp_us")
                  if lay.find_field("host_sync_timestamp_us_valid") is not None else None]
        self._stamps = [s for s in stamps if s is not None]
        if (vs.find_field("timestamp_us") is not None and stamps[0] is None) or (
                lay.find_field("host_sync_timestamp_us_valid") is not None and stamps[1] is None):
            raise ValueError(f"{NAME}: a time stamp is not a plain integer")
        self._rolling = _scalar(lay, "SPI_Rolling_Count")

    def encode(self, signals: Mapping[str, Any], now: float, rolling: int, counter: int,
               e2e: E2EState | None) -> bytes | None:
        """The message ``encode_dasp(NAME, veh_state_values(zero_values(), signals, now, api,
        rolling), counter, e2e)`` gives, or None (nothing changed, ``e2e`` included) where the
        template leaves it to the reference."""
        buf = bytearray(self._template)
        table = self._signals
        try:
            for k, v in signals.items():
                slot = table.get(k, _SKIP)
                if slot is _SKIP:
                    continue  # not a member of this release, or overwritten below
                if slot is _REFERENCE:
                    return None
                st, o = slot  # type: ignore[misc]
                st.pack_into(buf, o, v)
            if self._stamps:
                stamp = int(now * 1e6)
                for st, o in self._stamps:
                    st.pack_into(buf, o, stamp)
            if self._rolling is not None:
                self._rolling[0].pack_into(buf, self._rolling[1], rolling)
        except (struct.error, TypeError, ValueError, OverflowError):
            return None  # the reference raises or reports it
        if not 0 <= counter <= 255:
            return None
        self._protect(buf, e2e)
        return self._head + bytes((counter, 0)) + buf
