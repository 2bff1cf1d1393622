"""Application targets: every message decoder, the MESP client and server, the init bit codec,
and the host's and the simulated EyeQ's message handlers.

Oracles: decoders and handlers never raise for a peer's bytes (a problem is a counted event or a
``DecodedMessage.errors`` entry); the init codec either encodes a value (and its own check then
passes) or raises ``LocalProtocolError``, for any float (NaN, inf, huge); no input makes a step
run over its time limit; the host ends a CRC-valid EEPROM in Running Vision or FAILED with a
problem.
"""

from __future__ import annotations

import contextlib
import struct
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from eyeq_spi.catalog.messages import MessageDef, catalog
from eyeq_spi.codec.bits import BitSignalCodec
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.init_params import init_message
from eyeq_spi.codec.intrinsic import eeprom_codec, intrinsic_params_from_eeprom, seal_eeprom
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.emulator import Emulation
from eyeq_spi.errors import LocalProtocolError, SpecError
from eyeq_spi.faults.rig import Scene, rig
from eyeq_spi.host.machine import HostState
from eyeq_spi.mesp.client import MespClient
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.sim.eyeq import SimulatedEyeQ

from .core import FIGURES, Finding, Reader, time_limit

STEP_LIMIT = 2.0  # wall seconds one injected message may cost before it counts as a hang
NAN32 = 0x7FC00000


@lru_cache(maxsize=16)
def _codec(sw: str) -> MessageCodec:
    return MessageCodec(sw)


@lru_cache(maxsize=16)
def _server_sim(sw: str) -> SimulatedEyeQ:
    return SimulatedEyeQ(SimConfig(sw=sw))


def _sw(r: Reader) -> str:
    versions = catalog().sw_versions
    return str(versions[r.u8() % len(versions)])


def _payload(r: Reader, size: int) -> bytes:
    """``size`` bytes (sometimes a few more or fewer) from the input."""
    if r.u8() % 8 == 0:
        size = max(0, size + r.u8() % 9 - 4)
    chunk = r.take(r.u8()) or b"\0"
    return (chunk * (size // len(chunk) + 1))[:size]


def _message(r: Reader, codec: MessageCodec, direction: str | None) -> bytes:
    """One application message: DASP / 0x41 / 0x10 with the right header and size, MESP, raw."""
    cat = codec.cat
    kind = r.u8() % 5
    if kind <= 1:
        msgs = [m for m in cat.messages if (direction is None or m.direction == direction)
                and (m.protocol != "DASP" or m.exists_in(codec.sw))]
        if msgs:
            m: MessageDef = msgs[r.u16() % len(msgs)]
            try:
                size = codec.layout(m).size
            except SpecError:
                size = r.u8()
            body = _payload(r, size)
            if m.protocol == "DASP":
                reserved = 0 if r.u8() % 8 else r.u8()
                return bytes((0x65, m.data_id, r.u8(), reserved)) + body
            return bytes((m.data_id,)) + body
    if kind <= 3:
        f = cat.mesp[r.u8() % len(cat.mesp)]
        tag = r.u8() & (0xBF if direction == "h2e" else 0xFF)
        return bytes((f.service, 0x5E, f.service, f.function, tag)) + r.take(r.u8())
    return r.take(1 + r.u16() % 300)


def decoders(data: bytes) -> None:
    r = Reader(data)
    codec = _codec(_sw(r))
    msg = _message(r, codec, None)
    FIGURES["messages"] += 1
    out = codec.decode(msg, E2EState())
    if not out.errors and out.protocol == "UNKNOWN":
        raise Finding("an unknown message decoded without an error")
    _server_sim(str(codec.sw)).server.handle(msg)  # MESP server with the simulator's handlers
    client = MespClient(codec.cat)
    f = codec.cat.mesp[r.u8() % len(codec.cat.mesp)]
    params: dict[str, Any] = {p.name: "" if p.type == "string" else b"" if p.type == "bytes"
                              else 0 for p in f.request}
    client.request(f.name, params, now=0.0)
    req = client.data_to_send()[0]
    ret = b"\0\0\0\0" if r.u8() % 4 else r.take(4)
    client.receive_message(req[:4] + bytes((req[4] | 0x80,)) + ret + r.take(r.u16() % 400),
                           0.0)
    while client.next_event() is not None:
        pass


def _init_codec(r: Reader, sw: str) -> BitSignalCodec | None:
    defs = sorted(catalog().init_messages.values(), key=lambda d: d.name)
    d = defs[r.u8() % len(defs)]
    if d.name == "EEPROM_DATA":
        return eeprom_codec()
    try:
        return init_message(d.id, sw).codec
    except (LocalProtocolError, SpecError):
        return None


def init_codec(data: bytes) -> None:
    r = Reader(data)
    sw = _sw(r)
    codec = _init_codec(r, sw)
    if codec is None:
        return
    names = list(codec.signals)
    values = {names[r.u8() % len(names)]: r.number() for _ in range(1 + r.u8() % 8)}
    FIGURES["messages"] += 1
    try:
        wire = codec.encode(values)
    except LocalProtocolError:
        wire = None
    if wire is not None:
        if len(wire) != codec.length or codec.check(wire):
            raise Finding(f"encoded {values} into bytes its own check rejects: "
                          f"{codec.check(wire)}")
        codec.decode(wire)
    raw = r.take(codec.length).ljust(codec.length, b"\0")
    codec.decode(raw)
    codec.check(raw)
    if codec.message.name == "EEPROM_DATA":
        # SpecError: the release has no 0x84 table
        with contextlib.suppress(LocalProtocolError, SpecError):
            intrinsic_params_from_eeprom(seal_eeprom(raw + bytes(64)), sw)


def eeprom_image(r: Reader) -> tuple[bytes, list[str]]:
    """A CRC-valid EEPROM whose float signals may hold NaN, inf or any bits."""
    ee = eeprom_codec()
    img = bytearray(seal_eeprom(ee.encode()))
    word = int.from_bytes(img[: ee.length], "little")
    touched = []
    for _ in range(1 + r.u8() % 4):
        sig = ee.variant.signals[r.u8() % len(ee.variant.signals)]
        mask = (1 << sig.length) - 1
        pick = r.u8() % 4
        bits = NAN32 if pick == 0 and sig.length == 32 else \
            0x7F800000 if pick == 1 and sig.length == 32 else r.u32()
        word = (word & ~(mask << sig.start)) | ((bits & mask) << sig.start)
        touched.append(sig.name)
    img[: ee.length] = word.to_bytes(ee.length, "little")
    return seal_eeprom(bytes(img)), touched


def host_eeprom(data: bytes) -> None:
    r = Reader(data)
    image, touched = eeprom_image(r)
    emu = rig(fresh_nvm=True, scene=Scene(0, 0, 0))  # first ignition: Fatal 22 -> EEPROM
    emu.sim.eeprom[:] = image
    done = (HostState.RUNNING_VISION, HostState.FAILED)
    with time_limit(20 * STEP_LIMIT):
        emu.run_for(6.0, stop=lambda: emu.host.state in done)
    FIGURES["messages"] += 1
    if emu.host.state not in done:
        raise Finding(f"EEPROM with {touched}: host stuck in {emu.host.state.value}")
    if emu.host.state is HostState.FAILED and not emu.host.problem:
        raise Finding("host FAILED without a problem")


@dataclass
class _Live:
    emu: Emulation
    injected: int = 0


_LIVE: dict[str, _Live] = {}


def _live(side: str) -> _Live:
    live = _LIVE.get(side)
    if live is None or live.injected > 400 or live.emu.host.state in (
            HostState.FAILED, HostState.BOOT_FAILED, HostState.FATAL):
        emu = rig(scene=Scene(1, 1, 1))
        emu.run_for(2.0, stop=lambda: emu.host.state is HostState.RUNNING_VISION)
        live = _LIVE[side] = _Live(emu)
    return live


def _veh_state(r: Reader, codec: MessageCodec) -> bytes:
    """HOST_VEH_STATE_MSG with fuzzed values and a valid E2E protection, where it encodes."""
    msg = codec.message("HOST_VEH_STATE_MSG")
    values = codec.layout(msg).zero_values()
    vs = values["vehStateInfo"]
    for k in list(vs):
        if isinstance(vs[k], float) and r.u8() % 3 == 0:
            vs[k] = r.number()
    try:
        return codec.encode_dasp(msg.name, values, r.u8(), None)
    except (LocalProtocolError, ValueError, OverflowError, struct.error):
        return bytes((0x65, msg.data_id, r.u8(), 0)) + _payload(r, codec.layout(msg).size)


def _inject(data: bytes, side: str) -> None:
    r = Reader(data)
    live = _live(side)
    emu = live.emu
    sender = emu.sim if side == "host" else emu.host
    codec = sender.codec
    for _ in range(1 + r.u8() % 3):
        if side == "eyeq" and r.u8() % 2:
            msg = _veh_state(r, codec)
        else:
            msg = _message(r, codec, "e2h" if side == "host" else "h2e")
        if not msg:
            continue
        sender.conn.send(msg[: 512 if side == "eyeq" else 8191], emu.runner.now)
        FIGURES["messages"] += 1
        live.injected += 1
    try:
        with time_limit(STEP_LIMIT):
            emu.run_for(0.004)
    except BaseException:
        _LIVE.pop(side, None)  # its state is mid-step: the next input starts a fresh one
        raise


def host_messages(data: bytes) -> None:
    """Messages from the EyeQ's side into a host in Running Vision."""
    _inject(data, "host")


def sim_messages(data: bytes) -> None:
    """Messages from the host's side into a simulated EyeQ in Running Vision."""
    _inject(data, "eyeq")
