"""The Aurix host emulator: brings an EyeQ4 up and runs it in vision mode (and TAC/SPC/DV) over
the real link and transport. Sans-IO; the state machine is the table in ``machine.py``.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import AsyncIterator, Callable
from typing import Any

from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.init_params import init_message
from eyeq_spi.codec.message import DaspCounters, DecodedMessage, MessageCodec
from eyeq_spi.errors import CodecError, LocalProtocolError, SpecError
from eyeq_spi.host import calibration, init_seq
from eyeq_spi.host.config import (
    APP_IDS,
    DV_STATE,
    EEPROM_FILE,
    FATAL_INTRINSIC,
    PENDING,
    PENDING_OF,
    PENDING_VISION,
    RUNNING_SPC,
    RUNNING_TAC,
    RUNNING_VISION,
    STAGE_OF,
    STALE_CHECK,
    E,
    HostConfig,
    HostCounters,
    S,
    Transition,
    link_config,
)
from eyeq_spi.host.machine import HostEvent, HostState, next_state
from eyeq_spi.host.nvm import Nvm
from eyeq_spi.host.scenario import ConstantDrive, Scenario, veh_state_values
from eyeq_spi.link.events import Resynchronised
from eyeq_spi.mesp.client import MespClient, MespCompleted, MespFailed
from eyeq_spi.mesp.replies import MespError, MespReply
from eyeq_spi.spec.catalog import sw_release
from eyeq_spi.spec.tables import alignment_nvm
from eyeq_spi.transport.connection import TransportConnection
from eyeq_spi.transport.events import MessageReceived

SWITCH_APP = (0x05, 0x05)  # MESP Switch EyeQ Application (service, function), M3

ResetLine = Callable[[float], None]
Subscriber = Callable[[DecodedMessage], None]

__all__ = ["HostConfig", "HostCounters", "HostEmulator", "ResetLine", "Subscriber", "Transition"]


class HostEmulator:
    def __init__(
        self,
        config: HostConfig | None = None,
        *,
        nvm: Nvm | None = None,
        scenario: Scenario | None = None,
        reset_line: ResetLine | None = None,
        keep_rx_times: bool = True,
    ) -> None:
        self.config = config or HostConfig()
        self.codec = MessageCodec(self.config.sw)
        self.sw = self.codec.sw
        self.conn = TransportConnection(link_config("host", self.config.ack_timeout,
                                                     self.config.transmit_timeout))
        self.mesp = MespClient(self.codec.cat)
        self.nvm = nvm or Nvm()
        self.nvm.load()
        self.scenario = scenario or ConstantDrive()
        self.reset_line = reset_line
        self.counters = HostCounters()
        self.keep_rx_times = keep_rx_times
        self.state = S.POWER_UP
        self.transitions: list[Transition] = []
        self.problem: str | None = self.nvm.load_problem
        self.versions: dict[str, int] | None = None
        self.boot_info: dict[str, Any] = {}
        self.last_diag: dict[str, Any] = {}
        self.calibration_result: dict[str, Any] | None = None
        self._subscribers: list[Subscriber] = []
        self._queues: list[asyncio.Queue[DecodedMessage]] = []
        self._e2e = E2EState()  # D5: the EyeQ's rolling counters, judged afresh per boot
        # our own HOST_VEH_STATE rolling counters run on across EyeQ resets, as our DASP counter
        # does: a capture of the whole run then shows one unbroken sequence (the EyeQ's
        # restarted application takes whatever comes first)
        self._tx_e2e = E2EState()
        self._rx_counters = DaspCounters()
        self._last_rx: dict[str, float] = {}
        self._stale: set[str] = set()
        self._strikes = 0
        self._bringups = 0
        self._boot_deadline: float | None = None
        self._next_poll: float | None = None
        self._poll_busy = False
        self._veh_next: float | None = None
        self._rolling = 0
        self._dasp_counter = 0
        self._init_queue: deque[int] = deque()
        self._init_busy = False
        self._target_mode = "VISION"
        self._versions_asked = False
        self._versions_ok = False  # a positive Get EyeQ Versions reply in this ignition cycle
        self._switch_at: float | None = None  # when the last one was sent, until its ACK
        self._started = False
        self._stale_limits: dict[str, float] = {}
        self._next_stale_check = 0.0
        self.now = 0.0

    # -- public API -------------------------------------------------------------------------
    def start(self, now: float) -> None:
        """Ignition on: count the cycle, wait for the EyeQ's boot status."""
        self._started = True
        self.nvm.data.ignition_cycles += 1
        self._enter(S.POWER_UP, now)

    def subscribe(self, callback: Subscriber) -> None:
        self._subscribers.append(callback)

    def messages(self) -> AsyncIterator[DecodedMessage]:
        """Async iterator over delivered messages (one queue per iterator)."""
        q: asyncio.Queue[DecodedMessage] = asyncio.Queue()
        self._queues.append(q)

        async def gen() -> AsyncIterator[DecodedMessage]:
            while True:
                yield await q.get()

        return gen()

    def switch_mode(self, mode: str, now: float) -> None:
        """Go to TAC, SPC or DV, or back to VISION (§6 flow step 16)."""
        mode = mode.upper()
        if mode not in APP_IDS:
            raise LocalProtocolError(f"unknown mode {mode!r}: use VISION, TAC, SPC or DV")
        if self.state not in (S.RUNNING_VISION, S.RUNNING_TAC, S.RUNNING_SPC, S.DV):
            raise LocalProtocolError(f"cannot switch mode in state {self.state.value}")
        stage = STAGE_OF.get(mode)
        if stage is not None:
            try:
                init_message(stage, self.sw, self.codec.cat)
            except (SpecError, CodecError) as exc:
                # §7.1.1.7: the mode needs its init message; this release has no table for it
                raise LocalProtocolError(
                    f"{mode} is not available for SW {self.sw}: {exc}") from None
        self._target_mode = mode
        self._fire(E.SWITCH, now, mode)

    def link_restarted(self, now: float) -> None:
        """The byte stream to the EyeQ was re-established (a new connection is a power-up):
        restart our SPI driver and run the bring-up again."""
        self._cancel_requests()
        self._restart_driver()
        if next_state(self.state, E.EYEQ_RESET) is not None:
            self._fire(E.EYEQ_RESET, now, "link re-established")
        else:
            self._enter(S.POWER_UP, now)

    def warm_up(self) -> None:
        """Decode one message of each kind the EyeQ sends and encode HOST_VEH_STATE once, so
        that no first-time codec build delays an ACK in real time."""
        e2e = E2EState()
        for m in self.codec.cat.messages:
            if m.protocol == "DASP" and m.direction == "e2h" and m.exists_in(self.sw):
                lay = self.codec.layout(m)
                self.codec.decode(self.codec.encode_dasp(m.name, lay.zero_values(), 0, e2e),
                                  E2EState())
        msg = self.codec.message("HOST_VEH_STATE_MSG")
        self.codec.encode_dasp(msg.name, self.codec.layout(msg).zero_values(), 0, E2EState())
        self.mesp.codec.warm_up()  # MESP requests we send, replies we read
        self.codec.mesp.warm_up()

    # -- node interface ---------------------------------------------------------------------
    def receive_data(self, transfer: bytes, now: float) -> None:
        self.now = now
        self.conn.receive_data(transfer, now)
        self._pump(now)

    def data_to_send(self, now: float) -> list[bytes]:
        self._flush_mesp(now)
        return self.conn.data_to_send(now)

    def express_absorb(self, transfer: bytes, now: float) -> list[bytes] | None:
        """runner/virtual_fast.py: ``receive_data``, then ``handle_timer`` and ``data_to_send`` at
        the same ``now`` (as a runner calls them for a DATA frame, whose ACK makes the timer
        due), in one step, when the frame continues a message and completes nothing and no
        timer of the host is due: the ACK. None, with nothing changed, otherwise."""
        if self.mesp.waiting or (self.state is S.RUNNING_VISION
                                 and now >= self._next_stale_check):
            return None
        for t in (self.mesp.get_timer() if self.mesp.outstanding else None,
                  self._boot_deadline, self._next_poll, self._veh_next):
            if t is not None and t <= now:
                return None
        ack = self.conn.absorb(transfer, now)
        if ack is None:
            return None
        self.now = now
        return [ack]

    def get_timer(self) -> float | None:
        # asked after every event (runner/virtual.py): no temporary lists here
        best = self.conn.get_timer()
        for t in (self.mesp.get_timer() if self.mesp.outstanding else None,
                  self._boot_deadline, self._next_poll, self._veh_next,
                  self._next_stale_check if self.state is S.RUNNING_VISION and self._last_rx
                  else None):
            if t is not None and (best is None or t < best):
                best = t
        return best

    def handle_timer(self, now: float) -> None:
        self.now = now
        self.conn.handle_timer(now)
        self.mesp.handle_timer(now)
        if self._boot_deadline is not None and now >= self._boot_deadline:
            self._boot_deadline = None
            self._boot_failed(now, "no boot status within the timeout")
        if self._next_poll is not None and now >= self._next_poll and not self._poll_busy:
            self._next_poll = None
            self._poll_busy = True
            self.mesp.request("GetEyeQExtendedState", now=now)
        if self._veh_next is not None and now >= self._veh_next:
            self._send_veh_state(now)
            period = 1.0 / self.config.veh_state_rate
            self._veh_next = max(self._veh_next + period, now)
        if self.state is S.RUNNING_VISION and now >= self._next_stale_check:
            self._next_stale_check = now + STALE_CHECK
            self._check_stale(now)
        self._pump(now)

    # -- state machine ----------------------------------------------------------------------
    def _fire(self, event: HostEvent, now: float, detail: str = "") -> None:
        dst = next_state(self.state, event)
        if dst is None:
            self.counters.ignored_events += 1
            return
        self.transitions.append(Transition(now, self.state, event, dst, detail))
        self._enter(dst, now)

    def _enter(self, state: HostState, now: float) -> None:
        self.state = state
        self._next_poll = None
        self._poll_busy = False
        action = getattr(self, f"_on_{state.value.lower()}", None)
        if action is not None:
            action(now)

    def _on_power_up(self, now: float) -> None:
        self._veh_next = None
        self._boot_deadline = now + self.config.boot_timeout
        self._init_queue.clear()
        self._init_busy = False
        self._e2e = E2EState()
        self._rx_counters.clear()
        self._last_rx.clear()
        self._stale.clear()

    def _on_wait_pending(self, now: float) -> None:
        self._next_poll = now

    def _on_init(self, now: float) -> None:
        stages = [0x84] if init_seq.has_init_table(0x84, self.sw, self.codec.cat) else []
        if self.config.camera_only_aeb:
            stages += [0x78, 0x79]
        stages.append(0x92)
        self._init_queue = deque(stages)
        self._init_busy = False
        self._send_next_init(now)

    def _on_read_eeprom(self, now: float) -> None:
        self._veh_next = None
        self.mesp.request("FFSReadFile", {"filename": EEPROM_FILE}, now=now,
                          callback=lambda r: self._on_eeprom(r, self.now))

    def _on_wait_running(self, now: float) -> None:
        self._veh_next = now
        if not self._versions_asked:
            self._versions_asked = True  # once per ignition cycle (§6 flow step 12)
            self.mesp.request("GetEyeQVersions", now=now, callback=self._on_versions)
        self._next_poll = now

    def _on_running_vision(self, now: float) -> None:
        expected = self._expected_dasp("APP")
        self._last_rx = {m.name: now for m in expected}
        self._stale_limits = {m.name: self.config.stale_periods / (m.rate_hz or 18.0)
                              for m in expected}
        self._next_stale_check = now + STALE_CHECK
        self._stale.clear()

    def _on_fatal(self, now: float) -> None:
        self._last_rx.clear()  # stop expecting DASP (a fatal EyeQ sends none)

    def _on_switching(self, now: float) -> None:
        self._veh_next = None  # stop DASP first (§6 flow step 16)
        self._last_rx.clear()
        self.calibration_result = None
        self.mesp.request("SwitchEyeQApplication", {"applicationId": APP_IDS[self._target_mode]},
                          now=now, callback=self._on_switch_reply)

    def _on_wait_mode_pending(self, now: float) -> None:
        self._next_poll = now

    def _on_mode_init(self, now: float) -> None:
        stage = STAGE_OF[self._target_mode]
        self._send_init(stage, now, mode_init=True)

    def _on_wait_mode_running(self, now: float) -> None:
        self._next_poll = now

    # -- MESP results -----------------------------------------------------------------------
    def _flush_mesp(self, now: float) -> None:
        for m in self.mesp.data_to_send():
            sid = self.conn.send(m, now)  # the link's tag of its frames
            self.counters.sent["MESP"] += 1
            if (m[0], m[3]) == SWITCH_APP:
                # L10: the EyeQ that takes it starts over, and so does our link to it: our
                # frames after it are numbered from 0, its first frame after (NUM 0, RSP 0)
                # restarts our receiver
                self.conn.link.restart_after(sid, now, self.mesp.deadline)
                self._switch_at = now

    def _on_state_reply(self, reply: MespReply) -> None:
        now = self.now
        st = reply.value
        main, sub = st.mainState, st.subState
        if self.state is S.WAIT_PENDING and main == PENDING and sub == PENDING_VISION:
            self._fire(E.PENDING_VISION, now)
        elif self.state is S.WAIT_RUNNING and main == RUNNING_VISION:
            self._fire(E.RUNNING_VISION, now)
        elif self.state is S.WAIT_MODE_PENDING:
            if self._target_mode == "DV" and main == DV_STATE:
                self._fire(E.MODE_DV, now)
            elif main == PENDING and sub == PENDING_OF.get(self._target_mode):
                self._fire(E.MODE_VISION_PENDING if self._target_mode == "VISION"
                           else E.MODE_PENDING, now)
        elif self.state is S.WAIT_MODE_RUNNING:
            if main == RUNNING_TAC:
                self._fire(E.RUNNING_TAC, now)
            elif main == RUNNING_SPC:
                self._fire(E.RUNNING_SPC, now)
        if self.state in (S.WAIT_PENDING, S.WAIT_RUNNING, S.WAIT_MODE_PENDING,
                          S.WAIT_MODE_RUNNING) and self._next_poll is None:
            self._next_poll = now + self.config.poll_interval

    def _on_versions(self, result: MespReply | MespError) -> None:
        if isinstance(result, MespReply):
            v = result.value
            self.versions = {"apiVersionMajor": v.apiVersionMajor,
                             "apiVersionMinor": v.apiVersionMinor,
                             "eyeqSwVersionMajor": v.eyeqSwVersionMajor,
                             "eyeqSwVersionMinor": v.eyeqSwVersionMinor}
            self.nvm.data.versions = dict(self.versions)
            self._versions_ok = True
        else:
            self._versions_asked = False  # ask again on the next bring-up

    def _on_switch_reply(self, result: MespReply | MespError) -> None:
        if isinstance(result, MespReply):
            self._fire(E.SWITCH_ACCEPTED, self.now)
        else:
            self.problem = str(result)
            self._fire(E.SWITCH_REJECTED, self.now, str(result))

    def _on_eeprom(self, result: MespReply | MespError, now: float) -> None:
        if self.state is not S.READ_EEPROM:
            return
        if isinstance(result, MespError):
            self.problem = f"EEPROM read failed: {result}"
            self._fire(E.EEPROM_BAD, now, self.problem)
            return
        params = init_seq.eeprom_intrinsics(result.value.data, self.sw)
        if isinstance(params, str):
            self.problem = params
            self._fire(E.EEPROM_BAD, now, self.problem)
            return
        if self._bringups >= self.config.max_resets:
            self.problem = (f"intrinsic calibration still mismatched after {self._bringups} "
                            "EyeQ resets: repair or replace the camera")
            self._fire(E.EEPROM_BAD, now, self.problem)
            return
        self.nvm.data.intrinsic = params
        self.nvm.save()
        self._fire(E.EEPROM_OK, now, "NVM updated from EEPROM; resetting the EyeQ")
        self._reset_eyeq(now)

    # -- init messages ----------------------------------------------------------------------
    def _send_next_init(self, now: float) -> None:
        if self._init_busy:
            return
        if not self._init_queue:
            self._fire(E.INIT_DONE, now)
            return
        self._send_init(self._init_queue.popleft(), now, mode_init=False)

    def _send_init(self, stage: int, now: float, *, mode_init: bool) -> None:
        try:
            req = init_seq.init_request(stage, self.sw, self.codec.cat, self.nvm.data,
                                        self.config.ipb_params)
        except (CodecError, SpecError) as exc:
            self.problem = f"init message 0x{stage:02X} cannot be built: {exc}"
            self._fire(E.INIT_REJECTED, now, self.problem)
            return
        self._init_busy = True

        def done(result: MespReply | MespError) -> None:
            self._init_busy = False
            if isinstance(result, MespError):
                self.problem = f"init message 0x{stage:02X} rejected: {result}"
                self._fire(E.INIT_REJECTED, self.now, self.problem)
            elif mode_init:
                self._fire(E.MODE_PARAMS_ACCEPTED, self.now)
            elif self.state is S.INIT:
                self._send_next_init(self.now)

        self.mesp.request("EventCalibrationTool", req, now=now, callback=done)

    # -- receive ----------------------------------------------------------------------------
    def _pump(self, now: float) -> None:
        while (ev := self.conn.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                self._on_message(ev.data, now)
            elif isinstance(ev, Resynchronised):
                self._on_link_resync(ev, now)
        while (mev := self.mesp.next_event()) is not None:
            if isinstance(mev, MespCompleted) and mev.reply.function == "GetEyeQExtendedState":
                self._poll_busy = False
                self._on_state_reply(mev.reply)
            elif isinstance(mev, MespFailed) and mev.error.function == "GetEyeQExtendedState":
                self._poll_busy = False
                if self._next_poll is None and self.state in (
                        S.WAIT_PENDING, S.WAIT_RUNNING, S.WAIT_MODE_PENDING, S.WAIT_MODE_RUNNING):
                    self._next_poll = now + self.config.poll_interval
        self._flush_mesp(now)

    def _on_message(self, data: bytes, now: float) -> None:
        if self.mesp.receive_message(data, now):
            return
        dasp = data[:1] == b"\x65"
        # field values only when someone reads them: subscribers, async queues, a TAC/SPC
        # result; E2E, counters and lengths are checked either way
        fields = not dasp or bool(self._subscribers or self._queues) \
            or self.state in (S.RUNNING_TAC, S.RUNNING_SPC)
        out = self.codec.decode(data, self._e2e if dasp else None, fields=fields)
        name = out.name or out.protocol
        self.counters.received[name] += 1
        if self.keep_rx_times:
            self.counters.rx_times.setdefault(name, []).append(now)
        if out.protocol == "BOOT":
            self._on_boot(out, now)
        elif out.protocol == "DIAG":
            self._on_diag(out, now)
        elif out.protocol == "DASP":
            self._on_dasp(out, data, now)
        else:
            self.counters.decode_errors += 1

    def _on_boot(self, out: DecodedMessage, now: float) -> None:
        if out.errors:
            self.counters.decode_errors += 1
            return
        f = out.fields
        self.boot_info = init_seq.boot_info(f)
        if self.state is not S.POWER_UP:
            # a boot status we did not ask for: the EyeQ reset (by itself, or on our soft
            # reset); our link to it starts over in both directions (L10), and no request
            # from before the reset will be answered
            self.conn.restart()
            self._cancel_requests()
            self.counters.eyeq_resets += 1
            self._fire(E.EYEQ_RESET, now, "unexpected boot status")
        self._boot_deadline = None
        if f["TestResults"]:
            self._boot_failed(now, f"boot test bits 0x{f['TestResults']:04X}")
        else:
            self._strikes = 0
            self._fire(E.BOOT_OK, now)

    def _boot_failed(self, now: float, why: str) -> None:
        self._strikes += 1
        self.counters.boot_failures += 1
        if self._strikes >= self.config.boot_strikes:
            self.problem = f"EyeQ boot failed {self._strikes} times in a row ({why})"
            self._fire(E.BOOT_STRIKE_OUT, now, self.problem)
            return
        self._fire(E.BOOT_BAD, now, why)
        self._reset_eyeq(now)

    def _on_diag(self, out: DecodedMessage, now: float) -> None:
        if out.errors:
            self.counters.decode_errors += 1
            return
        prev = self.last_diag.get("Main_State")
        self.last_diag = out.fields
        main, fatal = out.fields["Main_State"], out.fields["Fatal_Error"]
        before_vision = self.state in (S.WAIT_PENDING, S.INIT, S.WAIT_RUNNING)
        if fatal == FATAL_INTRINSIC and before_vision:
            self._fire(E.FATAL_22, now, "0x41 Fatal_Error 22")
            return
        if fatal and self.state not in (S.FATAL, S.READ_EEPROM, S.FAILED, S.POWER_UP):
            self.problem = f"EyeQ fatal error {fatal}"
            self._fire(E.FATAL, now, self.problem)
            return
        # A running EyeQ never reports boot or pending again without a reset. Compare with the
        # mode, not with the previous 0x41: the host can reach Running Vision by a Get State
        # reply before any 0x41 has reported it (fault campaign defect 5).
        went_back = (self.state in (S.RUNNING_VISION, S.RUNNING_TAC, S.RUNNING_SPC)
                     and main in (0, PENDING) and prev is not None)
        if went_back:
            self.counters.eyeq_resets += 1
            self._fire(E.EYEQ_RESET, now, f"0x41 Main_State went back to {main}")
            self._enter_after_app_restart(now)

    def _on_link_resync(self, ev: Resynchronised, now: float) -> None:
        """The EyeQ's link started over (L6/L6a): NUM went back, so the EyeQ reset by itself.
        Its boot status was probably lost to out-of-window NAKs, so do not wait for it."""
        if ev.cause == "peer_restart" or (
                self._switch_at is not None and now - self._switch_at <= self.mesp.deadline):
            # L10: the EyeQ took our Switch EyeQ Application and started its link afresh, as
            # we did ours: the switch, not a reset of its own
            self._switch_at = None
            return
        if self.state in (S.POWER_UP, S.FAILED, S.BOOT_FAILED):
            return  # a boot status is awaited anyway (with its timeout), or we gave up
        self.counters.eyeq_resets += 1
        if next_state(self.state, E.EYEQ_RESET) is None:
            return
        self._fire(E.EYEQ_RESET, now, f"EyeQ link restarted at NUM {ev.num} ({ev.cause})")
        if self.reset_line is not None:
            # a clean power-up: both SPI drivers start over, the boot status arrives in window
            self._reset_eyeq(now, bringup=False)
        else:
            self._cancel_requests()
            self.conn.restart()  # L10: our transmitter numbers from 0 again as well
            self._enter_after_app_restart(now)

    def _enter_after_app_restart(self, now: float) -> None:
        # the application restarted without a boot status: skip the boot wait
        if self.state is S.POWER_UP:
            self._boot_deadline = None
            self._fire(E.BOOT_OK, now, "application restarted")

    def _on_dasp(self, out: DecodedMessage, data: bytes, now: float) -> None:
        data_id = out.header.get("data_id")
        if data_id is not None and self._rx_counters.check(data_id, out.header["counter"]) \
                is not None:
            self.counters.dasp_counter_gaps += 1
        e2e = [e for e in out.errors if e.startswith("E2E")]
        if e2e:
            self.counters.e2e_errors += len(e2e)
        if out.errors:
            if not e2e:
                self.counters.decode_errors += 1
            return  # a rejected structure is never delivered (D5)
        if out.name is not None:
            self._last_rx[out.name] = now
            self._stale.discard(out.name)
        if self.state is S.RUNNING_TAC and out.name == "EYEQ_TAC_CAL_MSG":
            self._on_cal_result("TAC", out.fields["tacCalParams"], now)
        elif self.state is S.RUNNING_SPC and out.name == "EYEQ_DYNAMIC_CAL_MSG":
            self._on_cal_result("SPC", out.fields["dynamicCalParams"], now)
        if self.state in (S.RUNNING_VISION, S.RUNNING_TAC, S.RUNNING_SPC):
            self._deliver(out)

    def _on_cal_result(self, mode: str, cal: dict[str, Any], now: float) -> None:
        if self.calibration_result is not None:
            return
        ok = calibration.outcome(self.codec.cat, self.sw, mode, cal)
        if ok is None:
            return  # still running
        self.calibration_result = {"mode": mode, "ok": ok, "time": now, **{
            k: cal[k] for k in ("distYaw", "distPitch", "roll", "phYaw", "phPitch") if k in cal}}
        if ok:  # §21: "update ... only when TAC, SPC or Autofix is successfully completed"
            self.nvm.data.alignment = alignment_nvm().apply(mode, self.nvm.data.alignment, cal)
            self.nvm.save()

    def _deliver(self, out: DecodedMessage) -> None:
        for cb in self._subscribers:
            cb(out)
        for q in self._queues:
            q.put_nowait(out)

    # -- stale detection --------------------------------------------------------------------
    def _expected_dasp(self, mode: str) -> list[Any]:
        return [m for m in self.codec.cat.messages
                if m.protocol == "DASP" and m.direction == "e2h" and m.exists_in(self.sw)
                and mode in m.modes]

    def _check_stale(self, now: float) -> None:
        for name, t in self._last_rx.items():
            limit = self._stale_limits.get(name)
            if limit is not None and name not in self._stale and now - t > limit:
                self._stale.add(name)
                self.counters.stale_events[name] += 1

    @property
    def stale_streams(self) -> set[str]:
        return set(self._stale)

    # -- transmit ---------------------------------------------------------------------------
    def _send_veh_state(self, now: float) -> None:
        msg = self.codec.message("HOST_VEH_STATE_MSG")
        self._rolling = (self._rolling + 1) & 0xFFFF
        values = veh_state_values(self.codec.layout(msg).zero_values(),
                                  self.scenario.signals(now), now, sw_release(self.sw),
                                  self._rolling)
        try:
            wire = self.codec.encode_dasp(msg.name, values, self._dasp_counter, self._tx_e2e)
        except CodecError as exc:
            self.problem = f"HOST_VEH_STATE_MSG cannot be encoded: {exc}"
            self._veh_next = None
            return
        self._dasp_counter = (self._dasp_counter + 1) & 0xFF
        self.conn.send(wire, now)
        self.counters.sent["HOST_VEH_STATE_MSG"] += 1
        if self.keep_rx_times:
            self.counters.tx_times.append(now)

    def _cancel_requests(self) -> None:
        """An EyeQ reset: outstanding MESP requests are lost. Get EyeQ Versions is asked again
        at the next bring-up unless it was answered (§6 flow step 12: once per ignition cycle,
        after a positive response)."""
        self.mesp.cancel_all()
        if not self._versions_ok:
            self._versions_asked = False

    def _restart_driver(self) -> None:
        """Our SPI driver starts over: NUM 0 (L4), and the EyeQ's first DATA frame after the
        reset sets E (L10); what was pending is dropped."""
        self._switch_at = None
        self.conn.reset(learn=True)
        while self.conn.next_event() is not None:
            pass

    def _reset_eyeq(self, now: float, *, bringup: bool = True) -> None:
        """Reset the EyeQ; ``bringup`` counts it against ``max_resets`` (EEPROM-driven)."""
        self._cancel_requests()
        if bringup:
            self._bringups += 1
        self._enter(S.POWER_UP, now)
        if self.reset_line is not None:
            # Both SPI drivers start over together: NUM 0, E 0 on each side (L4). Without this
            # the reset EyeQ's first frames (its boot status) fall outside our receive window.
            self._restart_driver()
            self.reset_line(now)
        else:
            # no reset line (a remote EyeQ): a soft reset by switching to the vision app
            self.mesp.request("SwitchEyeQApplication", {"applicationId": APP_IDS["VISION"]},
                              now=now)
            self._boot_deadline = None
            self._fire(E.BOOT_OK, now, "soft reset (no reset line)")
