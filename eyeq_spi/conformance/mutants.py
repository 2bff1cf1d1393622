"""Deliberately broken variants of our own simulated EyeQ and host, test-only (``--builtin
--mutant NAME``): the proof that the suite can fail (docs/conformance.md, "Proof that it can
fail"). ``expected`` names the cases a variant's bug violates."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.codec.message import DecodedMessage, is_mesp
from eyeq_spi.errors import UsageError
from eyeq_spi.host import init_seq
from eyeq_spi.host.events import diag_event
from eyeq_spi.host.host import HostConfig, HostEmulator
from eyeq_spi.host.machine import HostEvent, HostState
from eyeq_spi.host.nvm import Nvm
from eyeq_spi.host.scenario import Scenario
from eyeq_spi.host.vehicle_state import NAME, VehicleStateSender
from eyeq_spi.link.events import Resynchronised
from eyeq_spi.link.frame import DATA_SIZE, FrameCodec, FrameKind, NakReason
from eyeq_spi.mesp.replies import MespReply, MespResult
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.sim.eyeq import SimulatedEyeQ

_FRAMES = FrameCodec()
BOOT, RUNNING_VISION = 0x03, 0x02


def builtin_eyeq_config(sw: str | None) -> SimConfig:
    """Our simulated EyeQ as ``--builtin`` runs it: a light scene, 0.3 s calibrations."""
    return SimConfig(sw=sw, objects=1, signs=1, light_spots=1, tac_duration=0.3)


def _header(transfer: bytes) -> tuple[int, int, int, int]:
    return _FRAMES.unpack_header(int.from_bytes(transfer[:4], "little"))


def _is_reply(message: bytes) -> bool:
    return is_mesp(message) and bool(message[4] & 0x80)


Control = Callable[[bytes, int, int, int], tuple[bytes, float]]


def _earliest(timer: float | None, *dues: float) -> float | None:
    return min((due for due in (timer, *dues) if due is not None), default=None)


def _controls(out: list[bytes], now: float, control: Control,
              held: list[tuple[float, bytes]]) -> list[bytes]:
    """The link's output with every ACK/NAK passed through ``control(transfer, D, RSP, NUM)``,
    which returns the transfer to send (empty: dropped) and how long to hold it back."""
    ready = [transfer for due, transfer in held if due <= now]
    held[:] = [(due, transfer) for due, transfer in held if due > now]
    for transfer in out:
        d, _, rsp, num = _header(transfer)
        delay = 0.0
        if d in (FrameKind.ACK, FrameKind.NAK):
            transfer, delay = control(transfer, d, rsp, num)
        if delay > 0:
            held.append((now + delay, transfer))
        elif transfer:
            ready.append(transfer)
    return ready


# -- EyeQ mutants -----------------------------------------------------------------------------
class _LinkOutput(SimulatedEyeQ):
    """Rewrites the link's ACK/NAK output without touching the link."""

    def data_to_send(self, now: float) -> list[bytes]:
        return _controls(super().data_to_send(now), now, self.control, [])

    def control(self, transfer: bytes, d: int, rsp: int, num: int) -> tuple[bytes, float]:
        return transfer, 0.0


class NoAck(_LinkOutput):
    def control(self, transfer: bytes, d: int, rsp: int, num: int) -> tuple[bytes, float]:
        return (b"" if d == FrameKind.ACK and rsp % 4 == 3 else transfer), 0.0  # every 4th lost


class WrongRsp(_LinkOutput):
    def control(self, transfer: bytes, d: int, rsp: int, num: int) -> tuple[bytes, float]:
        return (_FRAMES.ack((rsp + 1) % 4096) if d == FrameKind.ACK else transfer), 0.0


class SilentOnBadCrc(_LinkOutput):
    def control(self, transfer: bytes, d: int, rsp: int, num: int) -> tuple[bytes, float]:
        # a frame with a bad CRC is dropped without its NAK 0x002 (L5)
        return (b"" if d == FrameKind.NAK and num == NakReason.CRC_MISMATCH else transfer), 0.0


class AckCrcRange(_LinkOutput):
    def control(self, transfer: bytes, d: int, rsp: int, num: int) -> tuple[bytes, float]:
        crc = _FRAMES.crc(transfer[:4] + bytes(DATA_SIZE))  # pad included: L3 says header only
        return transfer[:4] + crc.to_bytes(2, "little") + transfer[6:], 0.0


class Resends(SimulatedEyeQ):
    def __init__(self, config: SimConfig | None = None) -> None:
        super().__init__(config)
        self._unacked: dict[int, tuple[float, bytes]] = {}

    def receive_data(self, transfer: bytes, now: float) -> None:
        if len(transfer) == 128:
            d, _, rsp, _ = _header(transfer)
            if d in (FrameKind.ACK, FrameKind.NAK):
                self._unacked.pop(rsp, None)
        super().receive_data(transfer, now)

    def data_to_send(self, now: float) -> list[bytes]:
        out = super().data_to_send(now)
        for transfer in out:
            if _header(transfer)[0] == FrameKind.DATA and transfer[6] == 0x00:  # single frames
                self._unacked[_header(transfer)[3]] = (now, transfer)
        for num, (sent, transfer) in list(self._unacked.items()):
            if now - sent >= 0.011:
                del self._unacked[num]
                out.append(transfer)
        return out

    def get_timer(self) -> float | None:
        return _earliest(super().get_timer(), *(sent + 0.011 for sent, _ in self._unacked.values()))


class StretchedReplies(SimulatedEyeQ):
    """transmitTimeout not enforced (§6, L7): a long MESP reply before Running Vision (the
    EEPROM read) goes out one frame per ``STALL`` seconds, under the receiver's 25 ms silence
    abort (T6), so the message arrives but its frames span more than 25 ms."""

    STALL = 0.015

    def __init__(self, config: SimConfig | None = None) -> None:
        super().__init__(config)
        self._gap = self.conn.link.config.frame_gap
        self._timeout = self.conn.link.config.transmit_timeout
        self._left = 0  # DATA frames still to go at the stretched pace

    def _send(self, message: bytes, now: float) -> None:
        link = self.conn.link
        idle = not link.queued and not link.in_flight and self.main_state != RUNNING_VISION
        stretch = idle and _is_reply(message) and len(message) > 2 * DATA_SIZE
        if stretch:
            link.config.transmit_timeout = 3600.0  # the queue deadline is set at send time
        super()._send(message, now)
        if stretch:
            link.config.frame_gap = self.STALL
            self._left = link.queued

    def data_to_send(self, now: float) -> list[bytes]:
        out = super().data_to_send(now)
        if self._left > 0:
            self._left -= sum(1 for t in out if _header(t)[0] == FrameKind.DATA)
            if self._left <= 0:
                link = self.conn.link
                link.config.frame_gap = self._gap
                link.config.transmit_timeout = self._timeout
        return out


class _MessageOutput(SimulatedEyeQ):
    """Rewrites whole application messages before the transport segments them."""

    def _send(self, message: bytes, now: float) -> None:
        super()._send(self.rewrite(message), now)

    def rewrite(self, message: bytes) -> bytes:
        return message


class DaspCounterStuck(_MessageOutput):
    def rewrite(self, message: bytes) -> bytes:
        if message[:2] == b"\x65\xa0":
            return message[:2] + b"\x00" + message[3:]  # 0xA0's counter never moves
        return message


class E2eWrong(_MessageOutput):
    def rewrite(self, message: bytes) -> bytes:
        if message[:2] != b"\x65\xe3":
            return message
        lay = self.codec.layout(self.codec.cat.message("EYEQ_VIS_AEB_INFO_MSG"))
        offset = 4 + lay.crc_plan[0].crc_offset
        return message[:offset] + bytes((message[offset] ^ 0xFF,)) + message[offset + 1:]


class TagNotEchoed(_MessageOutput):
    def rewrite(self, message: bytes) -> bytes:
        if _is_reply(message) and message[0] == 0x05 and message[3] == 0x04:
            return message[:4] + bytes((0x80 | ((message[4] + 1) & 0x3F),)) + message[5:]
        return message


class UnknownRet1(_MessageOutput):
    def rewrite(self, message: bytes) -> bytes:
        if _is_reply(message) and message[5:9] == (2).to_bytes(4, "little"):
            return message[:5] + (1).to_bytes(4, "little") + message[9:]
        return message


class InitBeforePending(SimulatedEyeQ):
    def _calibration(self, params: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        if self.main_state == BOOT and params["ct_stage"] == 0x92:
            return self._cal_result(0x92, 0, params)  # accepted while still booting
        return super()._calibration(params)


class RunningWithoutVehState(SimulatedEyeQ):
    def _calibration(self, params: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        ret, out = super()._calibration(params)
        if params["ct_stage"] == 0x92 and ret == 0 and not self.fatal_error:
            self.main_state, self.sub_state = RUNNING_VISION, 0  # no HOST_VEH_STATE_MSG needed
            self._next_dasp.clear()
        return ret, out


class ReceiveLimit(SimulatedEyeQ):
    def __init__(self, config: SimConfig | None = None) -> None:
        super().__init__(config)
        self.conn.config.receive_limit = 8191  # the host's limit instead of 512


class AckPad(_LinkOutput):
    def control(self, transfer: bytes, d: int, rsp: int, num: int) -> tuple[bytes, float]:
        return transfer[:6] + b"\xaa" * DATA_SIZE, 0.0  # §6: "122 pad bytes set to 0"


# -- host mutants -----------------------------------------------------------------------------
class _HostLinkOutput(HostEmulator):
    """Rewrites or holds back the host link's ACK/NAK output without touching the link."""

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._held: list[tuple[float, bytes]] = []

    def data_to_send(self, now: float) -> list[bytes]:
        return _controls(super().data_to_send(now), now, self.control, self._held)

    def get_timer(self) -> float | None:
        return _earliest(super().get_timer(), *(due for due, _ in self._held))

    def control(self, transfer: bytes, d: int, rsp: int, num: int) -> tuple[bytes, float]:
        return transfer, 0.0


class HostLateAcks(_HostLinkOutput):
    def control(self, transfer: bytes, d: int, rsp: int, num: int) -> tuple[bytes, float]:
        return transfer, (0.012 if d == FrameKind.ACK and rsp % 2 else 0.0)


class HostAckPad(_HostLinkOutput):
    def control(self, transfer: bytes, d: int, rsp: int, num: int) -> tuple[bytes, float]:
        return transfer[:6] + b"\xaa" * DATA_SIZE, 0.0  # §6: "122 pad bytes set to 0"


class HostNoRenumber(HostEmulator):
    def _restart_link(self, now: float, after: int | None = None) -> None:
        if after is None:  # L10 not followed: the transmitter keeps its numbering
            link = self.conn.link
            num = link.next_num
            self.conn.restart()
            link.reset(tx_num=num, expected=link.expected_num)

    def _restart_driver(self) -> None:
        num = self.conn.link.next_num
        super()._restart_driver()
        self.conn.link.reset(tx_num=num, learn=True)


class HostLateRestart(HostEmulator):
    """Sees an EyeQ reset only when 0x41 ``Main_State`` goes back (no link resynchronisation),
    then restarts its link: its first frame has NUM 0 and its old RSP, not 0 (L10a)."""

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._last_rsp = 0
        self._restarted = False

    def _on_link_resync(self, ev: Resynchronised, now: float) -> None:
        return  # the boot status was lost: the reset is seen from 0x41 below

    def _on_diag(self, out: DecodedMessage, now: float) -> None:
        if not out.errors and diag_event(self.state, out.fields,
                                         self.last_diag.get("Main_State") is not None
                                         ) == "went_back":
            self.conn.restart()  # L10: both directions afresh, our NUMs from 0
            self._restarted = True
        super()._on_diag(out, now)

    def data_to_send(self, now: float) -> list[bytes]:
        out = []
        for transfer in super().data_to_send(now):
            d, _, rsp, num = _header(transfer)
            if d == FrameKind.DATA:
                if self._restarted and num == 0:
                    self._restarted = False
                    transfer = _FRAMES.data_frame(self._last_rsp, 0, transfer[6:])
                else:
                    self._last_rsp = rsp
            out.append(transfer)
        return out


class HostNoRetry(HostEmulator):
    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.mesp.max_attempts = 1


class NoEepromReread(HostEmulator):
    def entry_read_eeprom(self, now: float) -> None:
        if self.nvm.data.intrinsic:  # "the NVM already holds a calibration": gives up unread
            self.problem = "Fatal 22 with a calibration in NVM"
            self._fire(HostEvent.EEPROM_BAD, now, self.problem)
            return
        super().entry_read_eeprom(now)


class IgnoresEepromCrc(HostEmulator):
    def _on_eeprom(self, result: MespResult, now: float) -> None:
        if self.state is HostState.READ_EEPROM and isinstance(result, MespReply) \
                and isinstance(init_seq.eeprom_intrinsics(result.value.data, self.sw), str):
            self._fire(HostEvent.EEPROM_OK, now, "EEPROM CRC-16 not checked")
            self._reset_eyeq(now)
            return
        super()._on_eeprom(result, now)


class VersionsEveryBringUp(HostEmulator):
    def entry_start_vehicle_state(self, now: float) -> None:
        self._versions_asked = False
        super().entry_start_vehicle_state(now)


class _WrongCrcSender(VehicleStateSender):
    """HOST_VEH_STATE_MSG with one bit of its first E2E CRC flipped."""

    def encode(self, scenario: Scenario, now: float) -> bytes:
        wire = bytearray(super().encode(scenario, now))
        lay = self.codec.layout(self.codec.message(NAME))
        wire[4 + lay.crc_plan[0].crc_offset] ^= 0x01  # after the 4-byte DASP header
        return bytes(wire)


class HostE2eWrong(HostEmulator):
    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.veh_state = _WrongCrcSender(self.codec, self.config)


@dataclass(frozen=True)
class Mutant:
    name: str
    dut: str
    bug: str
    expected: frozenset[str]  # the cases this bug violates
    # cases whose precondition the bug removes: skip or inconclusive, never pass or fail
    masks: frozenset[str] = frozenset()
    eyeq: type[SimulatedEyeQ] = SimulatedEyeQ
    host: type[HostEmulator] = HostEmulator
    config: dict[str, Any] = field(default_factory=dict)  # set on its SimConfig or HostConfig


def _m(name: str, dut: str, bug: str, expected: set[str], **kw: Any) -> Mutant:
    return Mutant(name, dut, bug, frozenset(expected), **kw)


MUTANTS: dict[str, Mutant] = {m.name: m for m in (
    _m("eyeq-no-ack", "eyeq", "every 4th ACK is never sent", {"LINK-ACK"}, eyeq=NoAck),
    _m("eyeq-wrong-rsp", "eyeq", "ACK RSP is the frame's NUM + 1",
       {"LINK-ACK", "LINK-DUP"}, eyeq=WrongRsp),
    _m("eyeq-silent-on-bad-crc", "eyeq", "a frame with a bad CRC gets no NAK 0x002",
       {"LINK-NAK-CRC"}, eyeq=SilentOnBadCrc),
    _m("eyeq-unknown-ret-1", "eyeq", "an unknown service or function is answered with ret 1",
       {"MESP-UNKNOWN"}, eyeq=UnknownRet1),
    _m("eyeq-ack-crc-range", "eyeq", "ACK/NAK CRC computed over the pad bytes too",
       {"LINK-CRC"}, eyeq=AckCrcRange),
    _m("eyeq-ack-pad", "eyeq", "ACK and NAK pad bytes are 0xAA", {"LINK-PAD"}, eyeq=AckPad),
    _m("eyeq-resends", "eyeq", "a DATA frame not ACKed in time is sent again",
       {"LINK-NORESEND"}, eyeq=Resends),
    _m("eyeq-tx-timeout", "eyeq", "transmitTimeout not enforced: a long reply during "
       "bring-up goes out 15 ms per frame", {"LINK-TXTIMEOUT"}, eyeq=StretchedReplies),
    _m("eyeq-receive-limit", "eyeq", "accepts 8191-byte messages (limit 512)", {"TP-LIMIT"},
       eyeq=ReceiveLimit),
    _m("eyeq-tag-not-echoed", "eyeq", "Get Versions replies carry counter + 1",
       {"MESP-TAG"}, eyeq=TagNotEchoed,
       # TP-ABORT tells "aborted" from "answered" by Get Versions replies matched by tag
       masks=frozenset({"TP-ABORT"})),
    _m("eyeq-reply-600ms", "eyeq", "Get Versions replies leave after 600 ms",
       {"MESP-DEADLINE"}, config={"delay_replies": {"GetEyeQVersions": 0.6}}),
    _m("eyeq-dasp-counter-stuck", "eyeq", "the counter of 0xA0 stays 0", {"DASP-COUNTER"},
       eyeq=DaspCounterStuck),
    _m("eyeq-e2e-wrong", "eyeq", "crc_16 of EYEQ_VIS_AEB_INFO_MSG is wrong", {"DASP-E2E"},
       eyeq=E2eWrong),
    _m("eyeq-diag-30hz", "eyeq", "0x41 at 30 Hz", {"DIAG-RATE"}, config={"diag_rate": 30}),
    _m("eyeq-init-before-pending", "eyeq", "0x92 accepted while still booting",
       {"FLOW-PENDING"}, eyeq=InitBeforePending),
    _m("eyeq-running-without-veh-state", "eyeq",
       "Running Vision right after 0x92, before any HOST_VEH_STATE_MSG", {"FLOW-RUNNING"},
       eyeq=RunningWithoutVehState),
    _m("host-veh-50hz", "host", "HOST_VEH_STATE_MSG at 50 Hz",
       {"DASP-RATE-APP-HOST_VEH_STATE_MSG"}, config={"veh_state_rate": 50.0}),
    _m("host-no-eeprom-reread", "host", "on Fatal 22 with a calibration in NVM it gives up "
       "without reading the EEPROM", {"HOST-FATAL22"}, host=NoEepromReread,
       # in the eeprom_bad cycle it never reads the EEPROM either: its bad CRC goes unseen
       masks=frozenset({"HOST-EEPROM-BAD"})),
    _m("host-ignores-bad-eeprom", "host", "an EEPROM with a bad CRC-16 is taken as good: the "
       "host resets the EyeQ and carries on", {"HOST-EEPROM-BAD"}, host=IgnoresEepromCrc),
    _m("host-late-acks", "host", "every other ACK leaves 12 ms late (ackTimeout 10 ms)",
       {"LINK-ACK"}, host=HostLateAcks),
    _m("host-ack-pad", "host", "ACK and NAK pad bytes are 0xAA", {"LINK-PAD"},
       host=HostAckPad),
    _m("host-no-renumber", "host", "after resetting the EyeQ its frames keep their old "
       "numbering (L10)", {"LINK-NUM"}, host=HostNoRenumber),
    _m("host-no-retry", "host", "a timed-out MESP request is never retried",
       {"HOST-RETRY"}, host=HostNoRetry),
    _m("host-e2e-wrong", "host", "crc_16 of host_vehicle_state_t is wrong", {"DASP-E2E"},
       host=HostE2eWrong,
       # our EyeQ, like a real one, does not enter Running Vision on a HOST_VEH_STATE_MSG that
       # fails E2E: the probes, the stale stream and our reset that need it never run
       masks=frozenset({"LINK-NAK-CRC", "LINK-NAK-FORMAT", "LINK-NAK-WINDOW", "LINK-DUP",
                        "LINK-NORESEND",
                        "LINK-RESYNC", "TP-LIMIT", "HOST-EYEQ-RESET", "HOST-STALE"})),
)}

# Hosts that depart only from our recommendations: every case passes, with advice.
ADVISED: dict[str, Mutant] = {m.name: m for m in (
    _m("host-versions-every-bring-up", "host", "asks Get Versions at every bring-up",
       {"HOST-VERSIONS"}, host=VersionsEveryBringUp),
    _m("host-endless-boot-resets", "host", "resets a failing EyeQ 10 times",
       {"HOST-BOOT-RESETS"}, config={"boot_strikes": 10}),
)}

# Hosts that differ from ours but break no rule: every case gets the verdict ours gets.
CORRECT: dict[str, Mutant] = {m.name: m for m in (
    _m("host-late-restart", "host", "learns of an EyeQ reset only from 0x41 Main_State and "
       "then numbers its frames from 0 again, RSP not 0 (L10a)", set(),
       host=HostLateRestart),
)}


def _mutant(name: str | None, dut: str) -> Mutant:
    if name is None:
        return Mutant("", dut, "", frozenset())
    mutant = MUTANTS.get(name) or ADVISED.get(name) or CORRECT.get(name)
    if mutant is None or mutant.dut != dut:
        known = ", ".join(k for k, v in (MUTANTS | ADVISED | CORRECT).items() if v.dut == dut)
        raise UsageError(f"no {dut} mutant {name!r} (known: {known})")
    return mutant


def build_eyeq(name: str | None, sw: str | None) -> SimulatedEyeQ:
    mutant = _mutant(name, "eyeq")
    cfg = builtin_eyeq_config(sw)
    for key, value in mutant.config.items():
        setattr(cfg, key, value)
    return mutant.eyeq(cfg)


def build_host(name: str | None, sw: str | None, reset_line: Callable[[float], None],
               nvm: Nvm | None) -> HostEmulator:
    mutant = _mutant(name, "host")
    cfg = HostConfig(sw=sw)
    for key, value in mutant.config.items():
        setattr(cfg, key, value)
    return mutant.host(cfg, nvm=nvm, reset_line=reset_line, keep_rx_times=False)
