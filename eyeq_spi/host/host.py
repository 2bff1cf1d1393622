"""The Aurix host emulator: brings an EyeQ4 up and runs it in vision mode (and TAC/SPC/DV) over
the real link and transport (seed 004 §6 message flow, §7.1.1.1.4, §7.1.3). Sans-IO: every
method takes ``now``. Its states are the table of ``machine.py``; the ``entry_*`` methods are
the entry actions it names (a subclass overrides one, as the conformance mutants do)."""

from __future__ import annotations

from collections import deque
from collections.abc import AsyncIterator, Callable
from typing import Any

from eyeq_spi.catalog.bringup import EEPROM_FILE, SWITCH_APP
from eyeq_spi.catalog.tables import alignment_nvm
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import DaspCounters, DecodedMessage, MessageCodec
from eyeq_spi.errors import LocalProtocolError, SpecError
from eyeq_spi.host import calibration, init_seq
from eyeq_spi.host.config import (
    APP_IDS,
    STAGE_OF,
    HostConfig,
    HostCounters,
    Transition,
    link_config,
)
from eyeq_spi.host.events import VERSION_FIELDS, StatePoll, diag_event, state_reply_event
from eyeq_spi.host.link_health import with_link_cause
from eyeq_spi.host.machine import (
    ENTRY_ACTIONS,
    HostEvent,
    HostState,
    check_entry_handlers,
    next_state,
)
from eyeq_spi.host.nvm import Nvm
from eyeq_spi.host.scenario import ConstantDrive, Scenario
from eyeq_spi.host.streams import StreamWatch, expected_streams
from eyeq_spi.host.vehicle_state import VehicleStateSender
from eyeq_spi.link.events import Resynchronised
from eyeq_spi.mesp.client import MespClient, MespCompleted, MespFailed
from eyeq_spi.mesp.replies import MespFailure, MespReply, MespResult
from eyeq_spi.transport.connection import TransportConnection
from eyeq_spi.transport.events import MessageReceived

__all__ = ["HostConfig", "HostCounters", "HostEmulator", "ResetLine", "Subscriber",
           "Transition"]

ResetLine = Callable[[float], None]
Subscriber = Callable[[DecodedMessage], None]
TrafficSubscriber = Callable[[str, float], None]  # (message name, when it was counted)
EntryAction = Callable[[float], None]


class HostEmulator:
    """The host emulator as a sans-IO node: its state table's handlers, the bring-up they
    drive and the receive path."""

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        check_entry_handlers(cls, subclass=True)

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
        self.state = HostState.POWER_UP
        self.transitions: list[Transition] = []
        self.problem: str | None = self.nvm.load_problem
        self.versions: dict[str, int] | None = None
        self.boot_info: dict[str, Any] = {}
        self.last_diag: dict[str, Any] = {}
        self.calibration_result: dict[str, Any] | None = None
        self._subscribers: list[Subscriber] = []
        self._traffic_subscribers: list[TrafficSubscriber] = []
        self._e2e = E2EState()  # D5: the EyeQ's rolling counters, judged afresh per boot
        self._rx_counters = DaspCounters()
        self.veh_state = VehicleStateSender(self.codec, self.config)
        self.streams = StreamWatch()
        self._strikes = 0
        self._bringups = 0
        self._boot_deadline: float | None = None
        self.poll = StatePoll(self.config.poll_interval)
        self._init_queue: deque[int] = deque()
        self._init_busy = False
        self._target_mode = "VISION"
        self._versions_asked = False
        self._versions_ok = False  # a positive Get EyeQ Versions reply in this ignition cycle
        self._switch_at: float | None = None  # when the last one was sent, until its ACK
        self.now = 0.0
        # ENTRY_ACTIONS bound once: a subclass's override of a named method is what runs
        self._entry_actions: dict[HostState, EntryAction] = {
            state: getattr(self, name) for state, name in ENTRY_ACTIONS.items()}

    # -- public API -------------------------------------------------------------------------
    def start(self, now: float) -> None:
        """Ignition on: count the cycle, wait for the EyeQ's boot status."""
        self.nvm.data.ignition_cycles += 1
        self._enter(HostState.POWER_UP, now)

    def subscribe(self, callback: Subscriber) -> None:
        self._subscribers.append(callback)

    def subscribe_traffic(self, callback: TrafficSubscriber) -> None:
        """``callback(name, now)`` as the host counts a message received (delivered or not)
        or a HOST_VEH_STATE_MSG sent, whatever ``keep_rx_times`` says (a monitor's rates)."""
        self._traffic_subscribers.append(callback)

    def messages(self) -> AsyncIterator[DecodedMessage]:
        """Async iterator over delivered messages (one queue per iterator): the asyncio
        adapter ``runner/aio.py``, loaded only when asked for."""
        from eyeq_spi.runner.aio import message_stream

        return message_stream(self.subscribe)

    def switch_mode(self, mode: str, now: float) -> None:
        """Go to TAC, SPC or DV, or back to VISION (§6 flow step 16)."""
        mode = mode.upper()
        if mode not in APP_IDS:
            raise LocalProtocolError(f"unknown mode {mode!r}: use VISION, TAC, SPC or DV")
        if self.state not in (HostState.RUNNING_VISION, HostState.RUNNING_TAC,
                              HostState.RUNNING_SPC, HostState.DV):
            raise LocalProtocolError(f"cannot switch mode in state {self.state.value}")
        missing = init_seq.mode_unavailable(mode, self.sw, self.codec.cat)
        if missing is not None:
            raise LocalProtocolError(f"{mode} is not available for SW {self.sw}: {missing}")
        self._target_mode = mode
        self._fire(HostEvent.SWITCH, now, mode)

    def link_restarted(self, now: float) -> None:
        """The byte stream to the EyeQ was re-established (a new connection is a power-up):
        restart our SPI driver and run the bring-up again; a host that had given up starts its next
        ignition cycle."""
        self._cancel_requests()
        self._restart_driver()
        if self.state in (HostState.FAILED, HostState.BOOT_FAILED):
            self._next_ignition_cycle(now, "new connection after the host gave up")
        else:  # every other state takes an EyeQ reset (machine.py)
            self._fire(HostEvent.EYEQ_RESET, now, "link re-established")

    def _next_ignition_cycle(self, now: float, why: str) -> None:
        """Ignition off and on after the host gave up (§7.1.3 step 6: failed for this ignition
        cycle): the per-cycle state starts afresh; the run's counters and transitions go on."""
        self._cancel_requests()
        self._versions_asked = self._versions_ok = False
        self._strikes = self._bringups = 0
        self._target_mode = "VISION"
        self.problem = None
        self.calibration_result = None
        self.veh_state.new_cycle()
        self.nvm.data.ignition_cycles += 1
        self._fire(HostEvent.IGNITION, now, why)

    def warm_up(self) -> None:
        """Decode one message of each kind the EyeQ sends and encode HOST_VEH_STATE once, so
        that no first-time codec build delays an ACK in real time."""
        e2e = E2EState()
        for msg in self.codec.cat.messages:
            if msg.protocol == "DASP" and msg.direction == "e2h" and msg.exists_in(self.sw):
                lay = self.codec.layout(msg)
                self.codec.decode(self.codec.encode_dasp(msg.name, lay.zero_values(), 0, e2e),
                                  E2EState())
        self.veh_state.warm_up()
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

    def get_timer(self) -> float | None:
        # asked after every event (runner/virtual.py): no temporary lists here
        best = self.conn.get_timer()
        if self.mesp.outstanding:
            due = self.mesp.get_timer()
            if due is not None and (best is None or due < best):
                best = due
        due = self._boot_deadline
        if due is not None and (best is None or due < best):
            best = due
        due = self.poll.next_due
        if due is not None and (best is None or due < best):
            best = due
        due = self.veh_state.next_due
        if due is not None and (best is None or due < best):
            best = due
        if self.state is HostState.RUNNING_VISION and self.streams.last_rx:
            due = self.streams.next_check
            if best is None or due < best:
                best = due
        return best

    def handle_timer(self, now: float) -> None:
        self.now = now
        self.conn.handle_timer(now)
        self.mesp.handle_timer(now)
        if self._boot_deadline is not None and now >= self._boot_deadline:
            self._boot_deadline = None
            self._boot_failed(now, "no boot status within the timeout")
        if self.poll.due(now):
            self.poll.asked()
            self.mesp.request("GetEyeQExtendedState", now=now)
        if self.veh_state.due(now):
            self._send_veh_state(now)
            self.veh_state.advance(now)  # unless it could not be encoded (a problem)
        if self.state is HostState.RUNNING_VISION and now >= self.streams.next_check:
            self.streams.check(now, self.counters.stale_events)
        self._pump(now)

    # -- state machine and entry actions (ENTRY_ACTIONS in machine.py) --------------------
    def _fire(self, event: HostEvent, now: float, detail: str = "") -> None:
        dst = next_state(self.state, event)
        if dst is None:
            self.counters.ignored_events += 1
            return
        self.transitions.append(Transition(now, self.state, event, dst, detail))
        self._enter(dst, now)

    def _enter(self, state: HostState, now: float) -> None:
        self.state = state
        self.poll.stop()
        action = self._entry_actions.get(state)
        if action is not None:
            action(now)

    def entry_await_boot(self, now: float) -> None:
        self.veh_state.next_due = None
        self._boot_deadline = now + self.config.boot_timeout
        self._init_queue.clear()
        self._init_busy = False
        self._e2e = E2EState()
        self._rx_counters.clear()
        self.streams.clear()

    def entry_poll_state(self, now: float) -> None:
        self.poll.start(now)

    def entry_send_init(self, now: float) -> None:
        self._init_queue = deque(init_seq.stages(self.sw, self.codec.cat,
                                                 self.config.camera_only_aeb))
        self._init_busy = False
        self._send_next_init(now)

    def entry_read_eeprom(self, now: float) -> None:
        self.veh_state.next_due = None
        self.mesp.request("FFSReadFile", {"filename": EEPROM_FILE}, now=now,
                          callback=lambda r: self._on_eeprom(r, self.now))

    def entry_start_vehicle_state(self, now: float) -> None:
        self.veh_state.next_due = now
        if not self._versions_asked:
            self._versions_asked = True  # once per ignition cycle (§6 flow step 12)
            self.mesp.request("GetEyeQVersions", now=now, callback=self._on_versions)
        self.poll.start(now)

    def entry_watch_streams(self, now: float) -> None:
        self.streams.watch(expected_streams(self.codec.cat, self.sw, "APP"),
                           self.config.stale_periods, now)

    def entry_stop_watching(self, now: float) -> None:
        self.streams.stop()  # a fatal EyeQ sends no DASP

    def entry_request_switch(self, now: float) -> None:
        self.veh_state.next_due = None  # stop DASP first (§6 flow step 16)
        self.streams.stop()
        self.calibration_result = None
        self.mesp.request("SwitchEyeQApplication", {"applicationId": APP_IDS[self._target_mode]},
                          now=now, callback=self._on_switch_reply)

    def entry_send_mode_init(self, now: float) -> None:
        stage = STAGE_OF[self._target_mode]
        self._send_init(stage, now, mode_init=True)

    # -- MESP results -----------------------------------------------------------------------
    def _flush_mesp(self, now: float) -> None:
        if not self.mesp.waiting:
            return
        for request in self.mesp.data_to_send():
            sid = self.conn.send(request, now)  # the link's tag of its frames
            self.counters.sent["MESP"] += 1
            if (request[0], request[3]) == SWITCH_APP:
                # L10: the EyeQ that takes it starts over, and so does our link to it: our
                # frames after it are numbered from 0, its first frame after (NUM 0, RSP 0)
                # restarts our receiver
                self._restart_link(now, after=sid)
                self._switch_at = now

    def _restart_link(self, now: float, after: int | None = None) -> None:
        """L10: our link to the EyeQ starts over in both directions, now or, for a Switch EyeQ
        Application, after the frames of the link tag ``after``."""
        if after is None:
            self.conn.restart()
        else:
            self.conn.link.restart_after(after, now, self.mesp.deadline)

    def _on_state_reply(self, reply: MespReply) -> None:
        now = self.now
        event = state_reply_event(self.state, self._target_mode, reply.value.mainState,
                                  reply.value.subState)
        if event is not None:
            self._fire(event, now)
        self.poll.answered(self.state, now)

    def _on_versions(self, result: MespResult) -> None:
        if isinstance(result, MespReply):
            self.versions = {name: getattr(result.value, name) for name in VERSION_FIELDS}
            self.nvm.data.versions = dict(self.versions)
            self._versions_ok = True
        else:
            self._versions_asked = False  # ask again on the next bring-up

    def _on_switch_reply(self, result: MespResult) -> None:
        if isinstance(result, MespReply):
            self._fire(HostEvent.SWITCH_ACCEPTED, self.now)
        else:
            self.problem = str(result)
            self._fire(HostEvent.SWITCH_REJECTED, self.now, str(result))

    def _on_eeprom(self, result: MespResult, now: float) -> None:
        if self.state is not HostState.READ_EEPROM:
            return
        params = init_seq.eeprom_verdict(result, self.sw, self._bringups, self.config.max_resets)
        if isinstance(params, str):
            self.problem = params
            self._fire(HostEvent.EEPROM_BAD, now, self.problem)
            return
        self.nvm.data.intrinsic = params
        self.nvm.save()
        self._fire(HostEvent.EEPROM_OK, now, "NVM updated from EEPROM; resetting the EyeQ")
        self._reset_eyeq(now)

    # -- init messages ----------------------------------------------------------------------
    def _send_next_init(self, now: float) -> None:
        if self._init_busy:
            return
        if not self._init_queue:
            self._fire(HostEvent.INIT_DONE, now)
            return
        self._send_init(self._init_queue.popleft(), now, mode_init=False)

    def _send_init(self, stage: int, now: float, *, mode_init: bool) -> None:
        try:
            req = init_seq.init_request(stage, self.sw, self.codec.cat, self.nvm.data,
                                        self.config.ipb_params)
        except (LocalProtocolError, SpecError) as exc:
            self.problem = f"init message 0x{stage:02X} cannot be built: {exc}"
            self._fire(HostEvent.INIT_REJECTED, now, self.problem)
            return
        self._init_busy = True

        def done(result: MespResult) -> None:
            self._init_busy = False
            if isinstance(result, MespFailure):
                self.problem = with_link_cause(f"init message 0x{stage:02X} rejected: {result}",
                                               self.conn.link.counters)
                self._fire(HostEvent.INIT_REJECTED, self.now, self.problem)
            elif mode_init:
                self._fire(HostEvent.MODE_PARAMS_ACCEPTED, self.now)
            elif self.state is HostState.INIT:
                self._send_next_init(self.now)

        self.mesp.request("EventCalibrationTool", req, now=now, callback=done)

    # -- resets and streams -----------------------------------------------------------------
    def _cancel_requests(self) -> None:
        """An EyeQ reset loses the outstanding MESP requests; Get EyeQ Versions is asked again
        unless answered (§6 flow step 12: once per ignition cycle)."""
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
        self.counters.eyeq_resets_asked += 1
        if bringup:
            self._bringups += 1
        self._enter(HostState.POWER_UP, now)
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
            self._fire(HostEvent.BOOT_OK, now, "soft reset (no reset line)")

    # -- receive ----------------------------------------------------------------------------
    def _pump(self, now: float) -> None:
        while (ev := self.conn.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                self._on_message(ev.data, now)
            elif isinstance(ev, Resynchronised):
                self._on_link_resync(ev, now)
        while (mev := self.mesp.next_event()) is not None:
            if isinstance(mev, MespCompleted) and mev.reply.function == "GetEyeQExtendedState":
                self._on_state_reply(mev.reply)
            elif isinstance(mev, MespFailed) and mev.failure.function == "GetEyeQExtendedState":
                self.poll.answered(self.state, now)
        self._flush_mesp(now)

    def _on_message(self, data: bytes, now: float) -> None:
        if self.mesp.receive_message(data, now):
            return
        dasp = data[:1] == b"\x65"
        # field values only when someone reads them: subscribers (async iterators too), a
        # TAC/SPC result; E2E, counters and lengths are checked either way
        fields = not dasp or bool(self._subscribers) \
            or self.state in (HostState.RUNNING_TAC, HostState.RUNNING_SPC)
        out = self.codec.decode(data, self._e2e if dasp else None, fields=fields)
        name = out.name or out.protocol
        self.counters.received[name] += 1
        if self.keep_rx_times:
            self.counters.rx_times.setdefault(name, []).append(now)
        for callback in self._traffic_subscribers:
            callback(name, now)
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
        fields = out.fields
        self.boot_info = init_seq.boot_info(fields)
        if self.state is not HostState.POWER_UP:
            # a boot status we did not ask for: the EyeQ reset (by itself, or on our soft
            # reset); our link to it starts over in both directions (L10), and no request
            # from before the reset will be answered
            self._restart_link(now)
            self._cancel_requests()
            self.counters.eyeq_resets += 1
            self._fire(HostEvent.EYEQ_RESET, now, "unexpected boot status")
        self._boot_deadline = None
        if fields["TestResults"]:
            self._boot_failed(now, f"boot test bits 0x{fields['TestResults']:04X}")
        else:
            self._strikes = 0
            self._fire(HostEvent.BOOT_OK, now)

    def _boot_failed(self, now: float, why: str) -> None:
        self._strikes += 1
        self.counters.boot_failures += 1
        if self._strikes >= self.config.boot_strikes:
            self.problem = with_link_cause(
                f"EyeQ boot failed {self._strikes} times in a row ({why})", self.conn.link.counters)
            self._fire(HostEvent.BOOT_STRIKE_OUT, now, self.problem)
            return
        self._fire(HostEvent.BOOT_BAD, now, why)
        self._reset_eyeq(now)

    def _on_diag(self, out: DecodedMessage, now: float) -> None:
        if out.errors:
            self.counters.decode_errors += 1
            return
        event = diag_event(self.state, out.fields, self.last_diag.get("Main_State") is not None)
        self.last_diag = out.fields
        if event == "fatal_22":
            self._fire(HostEvent.FATAL_22, now, "0x41 Fatal_Error 22")
        elif event == "fatal":
            self.problem = f"EyeQ fatal error {out.fields['Fatal_Error']}"
            self._fire(HostEvent.FATAL, now, self.problem)
        elif event == "went_back":
            self.counters.eyeq_resets += 1
            self._fire(HostEvent.EYEQ_RESET, now,
                       f"0x41 Main_State went back to {out.fields['Main_State']}")
            self._enter_after_app_restart(now)

    def _on_link_resync(self, ev: Resynchronised, now: float) -> None:
        """The EyeQ's link started over (L6/L6a): NUM went back, so the EyeQ reset by itself.
        Its boot status was probably lost to out-of-window NAKs, so do not wait for it."""
        if ev.cause == "peer_restart" or (
                self._switch_at is not None and now - self._switch_at <= self.mesp.deadline):
            # L10: the EyeQ took our Switch EyeQ Application and started its link afresh, as
            # we did ours: the switch, not a reset of its own
            self._switch_at = None
            self.counters.restarts_answered += 1
            return
        if self.state in (HostState.POWER_UP, HostState.FAILED, HostState.BOOT_FAILED):
            return  # a boot status is awaited anyway (with its timeout), or we gave up
        self.counters.eyeq_resets += 1
        if next_state(self.state, HostEvent.EYEQ_RESET) is None:
            return
        self._fire(HostEvent.EYEQ_RESET, now, f"EyeQ link restarted at NUM {ev.num} ({ev.cause})")
        if self.reset_line is not None:
            # a clean power-up: both SPI drivers start over, the boot status arrives in window
            self._reset_eyeq(now, bringup=False)
        else:
            self._cancel_requests()
            self._restart_link(now)  # L10: our transmitter numbers from 0 again as well
            self._enter_after_app_restart(now)

    def _enter_after_app_restart(self, now: float) -> None:
        # the application restarted without a boot status: skip the boot wait
        if self.state is HostState.POWER_UP:
            self._boot_deadline = None
            self._fire(HostEvent.BOOT_OK, now, "application restarted")

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
            self.streams.received(out.name, now)
        if self.state is HostState.RUNNING_TAC and out.name == "EYEQ_TAC_CAL_MSG":
            self._on_cal_result("TAC", out.fields["tacCalParams"], now)
        elif self.state is HostState.RUNNING_SPC and out.name == "EYEQ_DYNAMIC_CAL_MSG":
            self._on_cal_result("SPC", out.fields["dynamicCalParams"], now)
        if self.state in (HostState.RUNNING_VISION, HostState.RUNNING_TAC, HostState.RUNNING_SPC):
            for callback in self._subscribers:
                callback(out)

    def _on_cal_result(self, mode: str, cal: dict[str, Any], now: float) -> None:
        if self.calibration_result is not None:
            return
        result = self.calibration_result = calibration.result(self.codec.cat, self.sw, mode,
                                                               cal, now)
        # §21: "update ... only when TAC, SPC or Autofix is successfully completed"
        if result is not None and result["ok"]:
            self.nvm.data.alignment = alignment_nvm().apply(mode, self.nvm.data.alignment, cal)
            self.nvm.save()

    @property
    def stale_streams(self) -> set[str]:
        return set(self.streams.stale)

    # -- transmit ---------------------------------------------------------------------------
    def _send_veh_state(self, now: float) -> None:
        try:
            wire = self.veh_state.encode(self.scenario, now)
        except LocalProtocolError as exc:
            self.problem = f"HOST_VEH_STATE_MSG cannot be encoded: {exc}"
            self.veh_state.next_due = None
            return
        self.conn.send(wire, now)
        self.counters.sent["HOST_VEH_STATE_MSG"] += 1
        if self.keep_rx_times:
            self.counters.tx_times.append(now)
        for callback in self._traffic_subscribers:
            callback("HOST_VEH_STATE_MSG", now)


check_entry_handlers(HostEmulator, subclass=False)
