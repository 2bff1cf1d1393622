"""The host's state and its bring-up (seed 004 §6 message flow, §7.1.1.1.4, §7.1.3): the state
machine of ``machine.py`` run with its entry actions, the init messages and the MESP replies that
move it, and the EyeQ resets. :class:`~eyeq_spi.host.host.HostEmulator` adds the node interface,
the receive path and the vehicle state. Sans-IO: every method takes ``now``.

Entry actions are the methods ``ENTRY_ACTIONS`` names (``entry_*``). A subclass changes one by
overriding that method (the conformance mutants do); a subclass that defines an ``entry_*`` method
the table does not name, or a method in the old ``_on_<state>`` style, fails at class creation.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any

from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import DaspCounters, DecodedMessage, MessageCodec
from eyeq_spi.errors import CodecError, SpecError
from eyeq_spi.host import init_seq
from eyeq_spi.host.config import (
    APP_IDS,
    DV_STATE,
    EEPROM_FILE,
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
from eyeq_spi.host.machine import ENTRY_ACTIONS, HostEvent, HostState, next_state
from eyeq_spi.host.nvm import Nvm
from eyeq_spi.host.scenario import ConstantDrive, Scenario
from eyeq_spi.mesp.client import MespClient
from eyeq_spi.mesp.replies import MespFailure, MespReply, MespResult
from eyeq_spi.transport.connection import TransportConnection

SWITCH_APP = (0x05, 0x05)  # MESP Switch EyeQ Application (service, function), M3

ResetLine = Callable[[float], None]
Subscriber = Callable[[DecodedMessage], None]
EntryAction = Callable[[float], None]


class HostBringUp:
    """The host's state, its state machine and the bring-up it drives."""

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        named = set(ENTRY_ACTIONS.values())
        stray = [n for n in vars(cls) if n.startswith("entry_") and n not in named]
        old = [n for n in vars(cls) if n in _OLD_STYLE]
        if stray or old:
            raise TypeError(
                f"{cls.__name__} defines {', '.join(stray + old)}, which no state runs: entry "
                f"actions are the methods named in host/machine.py ENTRY_ACTIONS "
                f"({', '.join(sorted(named))})")

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
        # HOST_VEH_STATE_MSG's template (host/veh_state_fast.py): (codec, packer), on first use
        self._veh_packed: tuple[Any, Any] | None = None
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
        # ENTRY_ACTIONS bound once: a subclass's override of a named method is what runs
        self._entry_actions: dict[HostState, EntryAction] = {
            state: getattr(self, name) for state, name in ENTRY_ACTIONS.items()}

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
        self._next_poll = None
        self._poll_busy = False
        action = self._entry_actions.get(state)
        if action is not None:
            action(now)

    def entry_await_boot(self, now: float) -> None:
        self._veh_next = None
        self._boot_deadline = now + self.config.boot_timeout
        self._init_queue.clear()
        self._init_busy = False
        self._e2e = E2EState()
        self._rx_counters.clear()
        self._last_rx.clear()
        self._stale.clear()

    def entry_poll_state(self, now: float) -> None:
        self._next_poll = now

    def entry_send_init(self, now: float) -> None:
        stages = [0x84] if init_seq.has_init_table(0x84, self.sw, self.codec.cat) else []
        if self.config.camera_only_aeb:
            stages += [0x78, 0x79]
        stages.append(0x92)
        self._init_queue = deque(stages)
        self._init_busy = False
        self._send_next_init(now)

    def entry_read_eeprom(self, now: float) -> None:
        self._veh_next = None
        self.mesp.request("FFSReadFile", {"filename": EEPROM_FILE}, now=now,
                          callback=lambda r: self._on_eeprom(r, self.now))

    def entry_start_vehicle_state(self, now: float) -> None:
        self._veh_next = now
        if not self._versions_asked:
            self._versions_asked = True  # once per ignition cycle (§6 flow step 12)
            self.mesp.request("GetEyeQVersions", now=now, callback=self._on_versions)
        self._next_poll = now

    def entry_watch_streams(self, now: float) -> None:
        expected = self._expected_dasp("APP")
        self._last_rx = {m.name: now for m in expected}
        self._stale_limits = {m.name: self.config.stale_periods / (m.rate_hz or 18.0)
                              for m in expected}
        self._next_stale_check = now + STALE_CHECK
        self._stale.clear()

    def entry_stop_watching(self, now: float) -> None:
        self._last_rx.clear()  # stop expecting DASP (a fatal EyeQ sends none)

    def entry_request_switch(self, now: float) -> None:
        self._veh_next = None  # stop DASP first (§6 flow step 16)
        self._last_rx.clear()
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

    def _on_versions(self, result: MespResult) -> None:
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

    def _on_switch_reply(self, result: MespResult) -> None:
        if isinstance(result, MespReply):
            self._fire(E.SWITCH_ACCEPTED, self.now)
        else:
            self.problem = str(result)
            self._fire(E.SWITCH_REJECTED, self.now, str(result))

    def _on_eeprom(self, result: MespResult, now: float) -> None:
        if self.state is not S.READ_EEPROM:
            return
        if isinstance(result, MespFailure):
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

        def done(result: MespResult) -> None:
            self._init_busy = False
            if isinstance(result, MespFailure):
                self.problem = f"init message 0x{stage:02X} rejected: {result}"
                self._fire(E.INIT_REJECTED, self.now, self.problem)
            elif mode_init:
                self._fire(E.MODE_PARAMS_ACCEPTED, self.now)
            elif self.state is S.INIT:
                self._send_next_init(self.now)

        self.mesp.request("EventCalibrationTool", req, now=now, callback=done)

    # -- resets and streams -----------------------------------------------------------------
    def _expected_dasp(self, mode: str) -> list[Any]:
        return [m for m in self.codec.cat.messages
                if m.protocol == "DASP" and m.direction == "e2h" and m.exists_in(self.sw)
                and mode in m.modes]


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


# every method ENTRY_ACTIONS names exists (a renamed or removed action fails at import), and
# the entry actions of the old naming, ``_on_<state>``, are refused in subclasses
_missing = [n for n in ENTRY_ACTIONS.values() if not callable(getattr(HostBringUp, n, None))]
if _missing:
    raise RuntimeError(f"ENTRY_ACTIONS names {', '.join(_missing)}, which HostBringUp lacks")
_OLD_STYLE = frozenset(f"_on_{state.value.lower()}" for state in HostState)
