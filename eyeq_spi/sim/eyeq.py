"""Simulated EyeQ4: boot status, 0x41 at 37 Hz, the application modes, the seven MESP functions
(§7.1.1, M3), periodic DASP at 18 Hz filled from a seeded numpy scene, and fault hooks. Sans-IO:
a runner feeds it transfers and ``now``.

Theory of operation
-------------------
``power_up(now)`` (or a reset) starts the boot (:class:`Phase`): after ``boot_delay`` the EyeQ
sends EYEQ_BOOT_STATUS_MSG (0x10). A boot with failure bits stays there; otherwise the application
starts ``app_start_delay`` later in Pending Vision and sends EYEQ_DIAGNOSTIC_MSG (0x41) at 37 Hz.

Modes (§7.1.1.1.1, §7.1.1.1.4, the 0x41 enums):

=================  =====================  ======================================================
mode               Main_State/Sub_State   leaves on
=================  =====================  ======================================================
Pending Vision     PENDING/PENDING_VISION 0x92 accepted + a HOST_VEH_STATE_MSG -> Running Vision
Running Vision     RUNNING_VISION         Switch Application
Pending TAC        PENDING/PENDING_TAC    0x85 accepted -> Running TAC
Running TAC        RUNNING_TAC            results after ``tac_duration``; Switch Application
Pending SPC        PENDING/PENDING_SPC    0x82 accepted -> Running SPC
Running SPC        RUNNING_SPC            results after ``tac_duration``; Switch Application
DV                 DV                     Switch Application
=================  =====================  ======================================================

Intrinsic calibration (§7.1.3, I2): the EyeQ compares the 0x84 it receives with its camera
EEPROM; on a mismatch it reports Fatal_Error 22 in 0x41 and will not enter vision. A subclass
changes a MESP answer by overriding its handler (the conformance mutants do).
"""

from __future__ import annotations

import enum
import math
from collections import Counter, deque
from typing import Any

from eyeq_spi.catalog.bringup import (
    APP_DV,
    APP_SPC,
    APP_TAC,
    APP_VISION,
    BOOT,
    EEPROM_FILE,
    FATAL_INTRINSIC,
    PENDING,
    PENDING_SPC,
    PENDING_TAC,
    PENDING_VISION,
    RUNNING_DV,
    RUNNING_SPC,
    RUNNING_TAC,
    RUNNING_VISION,
    SWITCH_APP,
)
from eyeq_spi.catalog.messages import MessageDef, sw_release
from eyeq_spi.catalog.schema import sw_key
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.init_params import init_message
from eyeq_spi.codec.intrinsic import (
    default_eeprom_image,
    version_bytes,
)
from eyeq_spi.codec.message import DaspCounters, MessageCodec, is_mesp
from eyeq_spi.errors import EyeqError, LocalProtocolError
from eyeq_spi.link.connection import LinkConfig
from eyeq_spi.mesp.server import (
    RET_BAD_PARAMETERS,
    RET_FILE_NOT_FOUND,
    RET_NOT_ALLOWED,
    MespServer,
)
from eyeq_spi.sim.calibration import expected_intrinsics, fill_calibration, strip_crc
from eyeq_spi.sim.config import MODE_OF_STATE, VEH_STATE_STALE, SimConfig, SimCounters
from eyeq_spi.sim.dasp_fast import DaspPacker
from eyeq_spi.sim.flash import FlashImage, hash_request
from eyeq_spi.sim.scene import Scene, SceneConfig
from eyeq_spi.transport.connection import TransportConnection
from eyeq_spi.transport.events import MessageReceived
from eyeq_spi.twins import references_only


class Phase(enum.Enum):
    """Where the EyeQ is between power and its application; each phase but the last two
    ends at ``SimulatedEyeQ.phase_due`` (``handle_timer`` moves it on)."""

    OFF = "off"  # no power: it hears and says nothing
    BOOTING = "booting"  # the boot status goes out at phase_due
    STARTING = "starting"  # the boot passed: the application starts at phase_due
    HALTED = "halted"  # the boot failed: nothing more until the next reset
    RUNNING = "running"  # the application: 0x41, MESP, DASP in the mode of main_state


class SimulatedEyeQ:
    SELF_CONTAINED = True  # runner/node.py: its calls act on nothing but this EyeQ

    def __init__(self, config: SimConfig | None = None) -> None:
        self.config = config or SimConfig()
        cfg = self.config
        self.codec = MessageCodec(cfg.sw)
        self.sw = self.codec.sw
        # The chosen release everywhere it appears on the wire: Get Versions, boot status, 0xA1.
        release = sw_release(self.sw)
        self.sw_version = cfg.sw_version or release
        self.api_version = cfg.api_version or release
        self.application_version = cfg.application_version or f"{release[0]}.{release[1]}.0"
        link = LinkConfig(role="eyeq")
        if cfg.ack_timeout is not None:
            link.ack_timeout = cfg.ack_timeout
        if cfg.transmit_timeout is not None:
            link.transmit_timeout = cfg.transmit_timeout
        self.conn = TransportConnection(link)
        self.eeprom = bytearray(default_eeprom_image())
        if cfg.corrupt_eeprom_crc:
            self.eeprom[0x4C] ^= 0xFF
        self.flash = FlashImage(cfg.flash_mb, cfg.seed)
        self.scene = Scene(SceneConfig(seed=cfg.seed, objects=cfg.objects, signs=cfg.signs,
                                       light_spots=cfg.light_spots,
                                       spot_angles_up=sw_key(self.sw) >= sw_key("sw4")))
        self.counters = SimCounters()
        self.e2e = E2EState()
        self.server = MespServer({
            "GetEyeQExtendedState": self._get_state,
            "GetEyeQVersions": self._get_versions,
            "SwitchEyeQApplication": self._switch_app,
            "FFSReadFile": self._ffs_read,
            "ComputeHash": self._compute_hash,
            "SendParamsToCalibrationTool": self._edr,
            "EventCalibrationTool": self._calibration,
        }, self.codec.cat)
        self._expected_0x84_no_crc = expected_intrinsics(bytes(self.eeprom), self.sw)
        self._replies: deque[tuple[float, bytes, bool]] = deque()  # (due, reply, late)
        self._dropped: Counter[str] = Counter()
        self._reply_deadline = float(self.codec.cat.raw["mesp.yaml"]["mesp"]["reply_deadline"])
        self._dasp_counter: Counter[int] = Counter()
        self._rx_counter = DaspCounters()
        self._templates: dict[str, dict[str, Any]] = {}
        self._dasp_sent = [  # the DASP messages it sends, in every mode
            m for m in self.codec.cat.messages
            if m.protocol == "DASP" and m.direction == "e2h" and m.exists_in(self.sw)]
        self._dasp_msgs: dict[str, list[MessageDef]] = {}  # mode -> the DASP messages it sends
        self._scene_frame: int | None = None  # the camera frame the scene was last stepped to
        self._dasp_min = 0.0  # min(_next_dasp.values()) when _next_dasp is not empty
        self._packers: dict[str, DaspPacker | None] = {}  # None: this message takes the reference
        self.phase = Phase.OFF
        self.phase_due: float | None = None  # when BOOTING or STARTING ends
        self.now = 0.0
        self._reset_done = False  # the configured reset (SimConfig.reset_at) happened
        self.main_state = 0
        self.sub_state = 0
        self.fatal_error = 0
        self._boot_number = 0
        self._init_ok = False  # 0x92 accepted in Pending Vision
        self._cal_started: float | None = None
        self._next_diag = 0.0
        self._next_dasp: dict[str, float] = {}
        self._process_index = 0
        self._ego: tuple[float | None, float | None] = (None, None)
        self._rx_e2e = E2EState()  # D5: verify the host's CRCs and rolling counters
        self._last_veh: float | None = None
        self.running_since: float | None = None  # first Running Vision of this power-up
        host_struct = self.codec.cat.structs.get("host_vehicle_state_t")
        var = host_struct.variant_for(self.sw) if host_struct is not None else None
        self._veh_ranges = {  # §7.1.2.2: the signals' declared ranges
            member.name: (float(member.min), float(member.max))
            for member in (var.members if var is not None else ())
            if member.min is not None and member.max is not None}

    def warm_up(self) -> None:
        """Build every template and codec path once before real time starts: the first message
        of each kind costs milliseconds, enough for the peer's 10 ms ackTimeout to expire."""
        e2e = E2EState()
        for msg in self._dasp_sent:
            values = dict(self._template(msg.name, msg.payload))
            self.scene.step(0.0, *self._ego)
            self._fill(msg.name, values, 0.0)
            self.codec.decode(self.codec.encode_dasp(msg.name, values, 0, e2e))
            packer = self._packer(msg)
            if packer is not None:
                self._fill(msg.name, packer.root, 0.0)  # type: ignore[arg-type]
                packer.encode(0, e2e)
                packer.reset()  # as the templates: the first real message starts from zeros
        self.server.codec.warm_up()  # MESP requests we read, replies we send
        self.codec.mesp.warm_up()
        self._templates.clear()
        self.counters.sent.clear()
        self.scene.world.unanchor()  # the first real step anchors the scene in time again

    # -- power ------------------------------------------------------------------------------
    def power_up(self, now: float) -> None:
        """Power-on or hardware reset: link, transport and application start over."""
        # L10: after a reset of ours the host's numbering is unknown: its first DATA frame
        # after the boot sets E. At the first power-up both sides start together at 0 (L4).
        self.conn.reset(learn=self.powered)
        while self.conn.next_event() is not None:
            pass
        # a reset loses the delayed replies: the host never gets them (late ones are counted)
        self.counters.mesp_replies_dropped += sum(not late for _, _, late in self._replies)
        self._replies.clear()
        self.phase, self.phase_due = Phase.BOOTING, now + self.config.boot_delay
        self.main_state = self.sub_state = 0
        self.fatal_error = 0
        self._rx_counter.clear()
        self.running_since = None
        self._restart_app()

    def _restart_app(self) -> None:
        """The application starts afresh: it judges the host's E2E rolling counters anew (as
        the host's restarted bring-up starts them anew), waits for 0x92 and restarts DASP."""
        self._rx_e2e = E2EState()
        self._last_veh = None
        self._init_ok = False
        self._cal_started = None
        self._next_dasp.clear()

    @property
    def powered(self) -> bool:
        return self.phase is not Phase.OFF

    @property
    def app_running(self) -> bool:
        return self.phase is Phase.RUNNING

    def _phase_over(self, now: float) -> bool:
        due = self.phase_due
        return due is not None and now >= due

    def _start_app(self, now: float) -> None:
        self.phase, self.phase_due = Phase.RUNNING, None
        self.main_state, self.sub_state = PENDING, PENDING_VISION
        self._init_ok = False
        self._next_diag = now

    # -- node interface ---------------------------------------------------------------------
    def receive_data(self, transfer: bytes, now: float) -> None:
        if self.phase is Phase.OFF:
            return
        self.now = now
        self.conn.receive_data(transfer, now)
        self._drain(now)

    def data_to_send(self, now: float) -> list[bytes]:
        return [] if self.phase is Phase.OFF else self.conn.data_to_send(now)

    def get_timer(self) -> float | None:
        if self.phase is Phase.OFF:
            return None
        best = self.conn.get_timer()
        own = self._own_timer()
        return own if best is None or (own is not None and own < best) else best

    def _own_timer(self) -> float | None:
        """The deadline of the EyeQ itself, its link's and transport's apart (asked after
        every event: straight comparisons, no temporary tuple)."""
        best = self.phase_due
        if not self._reset_done:
            due = self.config.reset_at
            if due is not None and (best is None or due < best):
                best = due
        if self._replies:
            due = self._replies[0][0]
            if best is None or due < best:
                best = due
        if self.phase is Phase.RUNNING:
            if best is None or self._next_diag < best:
                best = self._next_diag
            if self._dasp_mode() is not None:
                due = self._dasp_min if self._next_dasp else self.now
                if due < best:
                    best = due
        return best

    def handle_timer(self, now: float) -> None:
        if self.phase is Phase.OFF:
            return
        self.now = now
        cfg = self.config
        if cfg.reset_at is not None and not self._reset_done and now >= cfg.reset_at:
            self._reset_done = True
            self.counters.self_resets += 1
            self.power_up(now)
        self.conn.handle_timer(now)
        if self.phase is Phase.BOOTING and self._phase_over(now):
            self._send_boot_status(now)
        if self.phase is Phase.STARTING and self._phase_over(now):
            self._start_app(now)
        while self._replies and self._replies[0][0] <= now:
            self._send(self._replies.popleft()[1], now)
        if self.phase is Phase.RUNNING:
            if now >= self._next_diag:
                self._send_diag(now)
                self._next_diag = max(self._next_diag + 1.0 / cfg.diag_rate, now)
            self._send_due_dasp(now)
        self._drain(now)

    # -- receive ----------------------------------------------------------------------------
    def _drain(self, now: float) -> None:
        while (ev := self.conn.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                self._on_message(ev.data, now)

    def _on_message(self, data: bytes, now: float) -> None:
        if self.main_state == 0:
            if is_mesp(data) and (data[0], data[3]) == SWITCH_APP and not data[4] & 0x80:
                # the host's soft reset while we boot (or failed to): boot again, as a pulse
                # on the reset line would (a new boot status, counted against --boot-fail)
                self.power_up(now)
            return  # still booting: nobody listens yet
        if data[:1] == b"\x65":
            self._on_dasp(data, now)
            return
        reply = self.server.handle(data)
        if reply is None:
            self._bad_header()
            return
        self.counters.mesp_requests += 1
        self.counters.received["MESP"] += 1
        fn = self.codec.mesp.functions.get((data[0], data[3]))
        name = fn.name if fn else ""
        if self._dropped[name] < self.config.drop_replies.get(name, 0):
            self._dropped[name] += 1
            self.counters.mesp_replies_dropped += 1
            return
        delay = self.config.reply_delay + self.config.delay_replies.get(name, 0.0)
        late = delay >= self._reply_deadline
        self.counters.mesp_replies_late += late
        if delay > 0:
            self._replies.append((now + delay, reply, late))
        else:
            self._send(reply, now)

    def _on_dasp(self, data: bytes, now: float) -> None:
        out = self.codec.decode(data, self._rx_e2e)
        if out.name is None or any(e.startswith("BadHdr") for e in out.errors):
            self._bad_header()
            return
        self.counters.received[out.name] += 1
        if self._rx_counter.check(int(out.header["data_id"]), out.header["counter"]) is not None:
            self.counters.bad_seq = (self.counters.bad_seq + 1) & 0xFF
            self.counters.counter_gaps += 1
        if out.name == "HOST_VEH_STATE_MSG":
            self.counters.msg20_rx = (self.counters.msg20_rx + 1) & 0xFFFF
            self.counters.rolling_count_echo = int(out.fields.get("SPI_Rolling_Count", 0))
            if self.main_state == RUNNING_VISION and self._last_veh is not None \
                    and now - self._last_veh > VEH_STATE_STALE:
                self.counters.veh_state_stale += 1
            self._last_veh = now
            if out.errors:  # D5: a rejected structure never drives the scene
                self.counters.e2e_errors += 1
                return
            vs = out.fields.get("vehStateInfo", {})
            self._ego = (self._vehicle_signal(vs, "vehicleVelocity"),
                         self._vehicle_signal(vs, "vehicleYawRate"))
            if self.main_state == PENDING and self.sub_state == PENDING_VISION \
                    and self._init_ok and self.fatal_error == 0:
                self.main_state, self.sub_state = RUNNING_VISION, 0
                if self.running_since is None:
                    self.running_since = round(now, 4)
                self._next_dasp.clear()

    def _bad_header(self) -> None:
        self.counters.bad_hdr = (self.counters.bad_hdr + 1) & 0xFF
        self.counters.bad_hdr_total += 1

    def _vehicle_signal(self, vs: dict[str, Any], name: str) -> float | None:
        """A host signal the scene may use: flagged valid, finite and inside the seed's range
        (§7.1.2.2 host_vehicle_state_t); otherwise None (the scene keeps its last value)."""
        value = vs.get(name)
        valid = vs.get(f"{name}Validity", 1)
        lo, hi = self._veh_ranges.get(name, (-math.inf, math.inf))
        if value is None:
            return None
        if valid != 1 or not isinstance(value, int | float) or not math.isfinite(value) \
                or not lo <= value <= hi:
            self.counters.rejected_values += 1
            return None
        return float(value)

    # -- transmit ---------------------------------------------------------------------------
    def _send(self, message: bytes, now: float) -> None:
        self.conn.send(message, now)
        self.counters.msg_tx = (self.counters.msg_tx + 1) & 0xFFFF

    def _send_boot_status(self, now: float) -> None:
        cfg = self.config
        self._boot_number += 1
        self.counters.boots += 1
        failing = self._boot_number <= cfg.boot_failures
        values = self.codec.layout(self.codec.cat.message("EYEQ_BOOT_STATUS_MSG")).zero_values()
        values.update({
            "ProtocolVersion": 1,
            "TestResults": cfg.boot_test_failures if failing else 0,
            "BootVersion": list(version_bytes(cfg.boot_version)),
            "ApplicationVersion": list(version_bytes(self.application_version)),
            "EyeQType": cfg.eyeq_type, "EyeQID": cfg.eyeq_id,
            "BootStageCompleted": 5 if not failing else 1,
            "EyeQTemperatureSensor1": 45, "EyeQTemperatureSensor2": 46,
        })
        self._send(self.codec.encode_other("BOOT", values), now)
        self.counters.sent["EYEQ_BOOT_STATUS_MSG"] += 1
        if failing:
            self.phase, self.phase_due = Phase.HALTED, None
        else:
            self.main_state, self.sub_state = BOOT, 0  # MESP answers while the app starts
            self.phase, self.phase_due = Phase.STARTING, now + cfg.app_start_delay

    def _send_diag(self, now: float) -> None:
        cfg = self.config
        self._process_index += 1
        msg = self.codec.cat.message("EYEQ_DIAGNOSTIC_MSG")
        values = self._template(msg.name, msg.payload)
        fatal = cfg.fatal_error if cfg.fatal_error is not None else self.fatal_error
        ms = int(now * 1000) & 0xFFFFFFFF
        values.update({
            "Application_Message_Version": 1, "Main_State": self.main_state,
            "Sub_State": self.sub_state, "EyeQ_Process_Index": self._process_index,
            "EyeQ_Timestamp": ms, "EyeQ_Current_Timestamp": ms, "Fatal_Error": fatal,
            "Temperature_MIPS": 55, "Temperature_VMP": 57, "CameraInformation": 1,
            "Camera1_temperature": 40,
        })
        self._send(self.codec.encode_other("DIAG", values), now)
        self.counters.sent[msg.name] += 1

    def _dasp_mode(self) -> str | None:
        return MODE_OF_STATE.get(self.main_state)

    def _template(self, name: str, payload: str) -> dict[str, Any]:
        template = self._templates.get(name)
        if template is None:
            template = self.codec.layouts.get(payload, self.sw).zero_values()
            self._templates[name] = template
        return template

    def _send_due_dasp(self, now: float) -> None:
        mode = self._dasp_mode()
        if mode is None:
            return
        msgs = self._dasp_msgs.get(mode)
        if msgs is None:
            msgs = self._dasp_msgs[mode] = [m for m in self._dasp_sent if mode in m.modes]
        rate = self.config.dasp_rate
        period = 1.0 / rate
        if not self._next_dasp:
            # the streams (re)start: the scene resumes where it stood (catching up the whole
            # pause in one step held the loop past the host's 10 ms ackTimeout), and the
            # messages are staggered over one period (none waits past transmitTimeout)
            self.scene.world.unanchor()
            for index, msg in enumerate(msgs):
                self._next_dasp[msg.name] = now + index * period / max(1, len(msgs))
        # the messages due now, in catalogue order (a message not yet scheduled is due now)
        due = [(due_at, msg) for msg in msgs
               if (due_at := self._next_dasp.get(msg.name, now)) <= now]
        for due_at, msg in due:
            # §7.1.4: the scene moves once per camera frame (at the frame's start), and every
            # message of that frame reads the same state
            frame = math.floor(now * rate + 1e-6)
            if frame != self._scene_frame:
                self._scene_frame = frame
                self.scene.step(min(now, frame * period), *self._ego)
            self._next_dasp[msg.name] = max(due_at + period, now)
            stop = self.config.stop_dasp.get(msg.name)
            if stop is not None and now >= stop:
                continue
            counter = self._dasp_counter[msg.data_id]
            self._dasp_counter[msg.data_id] = (counter + 1) & 0xFF
            self._send(self._dasp_bytes(msg, counter, now), now)
            self.counters.sent[msg.name] += 1
        self._dasp_min = min(self._next_dasp.values(), default=now)

    def _packer(self, msg: MessageDef) -> DaspPacker | None:
        """The message's packer; None: the reference (switched off, by the config or, when the
        config leaves it open, by ``EYEQ_SPI_EXACT=1``; or no packer for it)."""
        if msg.name not in self._packers:
            packed = self.config.dasp_packer
            packed = not references_only() if packed is None else packed
            self._packers[msg.name] = DaspPacker.build(self.codec.layout(msg), msg.data_id) \
                if packed else None
        return self._packers[msg.name]

    def _dasp_bytes(self, msg: MessageDef, counter: int, now: float) -> bytes:
        """One DASP message: packed in place, or by the reference."""
        packer = self._packer(msg)
        if packer is not None:
            self._fill(msg.name, packer.root, now)  # type: ignore[arg-type]
            return packer.encode(counter, self.e2e)
        values = self._template(msg.name, msg.payload)
        self._fill(msg.name, values, now)
        return self.codec.encode_dasp(msg.name, values, counter, self.e2e)

    def _fill(self, name: str, values: dict[str, Any], now: float) -> None:
        if "timestamp_ms" in values:
            values["timestamp_ms"] = int(now * 1000) & 0xFFFFFFFF
        if name == "EYEQ_BASE_DIAG_STATUS_MSG":
            counters = self.counters
            values.update({**self._versions(),
                           "SPI_Rolling_Count_Echo": counters.rolling_count_echo & 0xFFFF,
                           "eyeqSPIMsgTxCtr": counters.msg_tx & 0xFFFF,
                           "eyeqSPIMsgRxBadHdrCtr": counters.bad_hdr & 0xFF,
                           "eyeqSPIMsgRxBadSeqCtr": counters.bad_seq & 0xFF})
            for key in ("eyeqSPIMsg20RxCtr", "eyeqSPIMsg10RxCtr"):
                if key in values:
                    values[key] = counters.msg20_rx & 0xFFFF
            if "spiDiagnosticInfo" in values:
                values["spiDiagnosticInfo"] = self.conn.link.counters.seed_view()
            return
        if name in ("EYEQ_TAC_CAL_MSG", "EYEQ_DYNAMIC_CAL_MSG") and self._cal_started is not None:
            fill_calibration(name, values, now, self._cal_started, self.config.tac_duration,
                             self.config.seed, self.config.tac_error)
            return
        self.scene.fill(name, values, now)

    # -- MESP functions (§7.1.1, M3) -------------------------------------------------------
    def _get_state(self, params: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        return 0, {"mainState": self.main_state, "subState": self.sub_state}

    def _versions(self) -> dict[str, int]:
        """The release as Get EyeQ Versions and EYEQ_BASE_DIAG_STATUS_MSG report it."""
        return {"apiVersionMajor": self.api_version[0], "apiVersionMinor": self.api_version[1],
                "eyeqSwVersionMajor": self.sw_version[0],
                "eyeqSwVersionMinor": self.sw_version[1]}

    def _get_versions(self, params: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        return 0, self._versions()

    def _switch_app(self, params: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        app = params["applicationId"]
        target = {APP_VISION: (PENDING, PENDING_VISION), APP_TAC: (PENDING, PENDING_TAC),
                  APP_SPC: (PENDING, PENDING_SPC), APP_DV: (RUNNING_DV, 0)}.get(app)
        if target is None:
            return RET_BAD_PARAMETERS, {}
        if self.fatal_error and app != APP_VISION:
            return RET_NOT_ALLOWED, {}
        stage = {APP_TAC: 0x85, APP_SPC: 0x82}.get(app)
        if stage is not None:
            try:
                init_message(stage, self.sw)
            except EyeqError:  # this release has no init table for the mode (§7.1.1.7)
                return RET_NOT_ALLOWED, {}
        if app == APP_VISION:
            self.counters.vision_switches += 1
            self.fatal_error = 0  # a restart of the vision application (the host's soft reset)
        self.main_state, self.sub_state = target
        self._restart_app()
        # L10: the host takes an accepted switch for a reset of ours; both link directions
        # start afresh (the reply is our first frame numbered from 0)
        self.conn.restart()
        return 0, {"applicationId": app}

    def _ffs_read(self, params: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        if params["filename"] != EEPROM_FILE:
            return RET_FILE_NOT_FOUND, {}
        return 0, {"lastModified": 0, "flags": 0, "desc": "camera EEPROM",
                   "data": bytes(self.eeprom)}

    def _compute_hash(self, params: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        ret, result = hash_request(self.flash, params["hashType"], params["datasetType"],
                                   params["start"], params["size"])
        if ret:
            return ret, {}
        return 0, {"hashType": params["hashType"], "datasetType": params["datasetType"],
                   "result": result}

    def _edr(self, params: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        if params["edr_type"] != 6 or params["edr_params_num"] != len(params["params"]):
            return RET_BAD_PARAMETERS, {}
        self.counters.edr_triggers.append({**params, "time": self.now})
        return 0, {k: params[k] for k in ("edr_type", "edr_policy", "edr_function")}

    def _calibration(self, request: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        stage, params = request["ct_stage"], request["params"]
        try:
            msg = init_message(stage, self.sw)
        except (LocalProtocolError, EyeqError):
            msg = None
        if msg is None or request["ct_type"] != msg.ct_type or (msg.codec is not None and (
                len(params) != msg.codec.length or msg.check(params))):
            return self._cal_result(stage, RET_BAD_PARAMETERS, request)
        allowed = {0x84: PENDING_VISION, 0x78: PENDING_VISION, 0x79: PENDING_VISION,
                   0x92: PENDING_VISION, 0x85: PENDING_TAC, 0x82: PENDING_SPC}
        if self.main_state != PENDING or self.sub_state != allowed.get(stage):
            return self._cal_result(stage, RET_NOT_ALLOWED, request)
        if stage == 0x84:
            assert msg.codec is not None
            if (self._expected_0x84_no_crc is not None
                    and strip_crc(msg.codec, params) != self._expected_0x84_no_crc):
                self.fatal_error = FATAL_INTRINSIC  # §7.1.3: NVM does not match the EEPROM
        elif stage == 0x92:
            self._init_ok = True
        elif stage in (0x85, 0x82):
            self.main_state, self.sub_state = (RUNNING_TAC if stage == 0x85 else RUNNING_SPC), 0
            self._cal_started = self.now
            self._next_dasp.clear()
        return self._cal_result(stage, 0, request)

    def _cal_result(self, stage: int, ret: int, request: dict[str, Any]
                    ) -> tuple[int, dict[str, Any]]:
        self.counters.calibration_events.append((stage, ret))
        return ret, {k: request[k] for k in ("ct_type", "ct_stage", "ct_version")}
