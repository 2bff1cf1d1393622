"""The simulated EyeQ's modes (the 0x41 Main_State/Sub_State values, seed 004 §7.1.1.1.4, M7),
its counters, and its answers to the seven MESP functions (§7.1.1, M3): Get Extended State, Get
Versions, Switch Application, FFS Read File, Compute Hash, Send Params To Calibration Tool
(EDR) and Event Calibration Tool (the init messages). :class:`MespFunctions` is the part of
:class:`~eyeq_spi.sim.eyeq.SimulatedEyeQ` that its ``MespServer`` dispatches to; a subclass
changes an answer by overriding the method (the conformance mutants do).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.catalog.bringup import (
    APP_DV,
    APP_SPC,
    APP_TAC,
    APP_VISION,
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
)
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.init_params import init_message
from eyeq_spi.errors import EyeqError, LocalProtocolError
from eyeq_spi.mesp.server import RET_BAD_PARAMETERS, RET_FILE_NOT_FOUND, RET_NOT_ALLOWED
from eyeq_spi.sim.calibration import strip_crc
from eyeq_spi.sim.flash import FlashImage, hash_request
from eyeq_spi.transport.connection import TransportConnection

VEH_STATE_STALE = 3 / 66.67  # three HOST_VEH_STATE periods (§7.1.2.2: 66.67 Hz)
MODE_OF_STATE = {RUNNING_VISION: "APP", RUNNING_TAC: "TAC", RUNNING_SPC: "SPC"}


@dataclass
class SimCounters:
    """What the simulator really received (reported in 0xA0)."""

    msg20_rx: int = 0
    bad_hdr: int = 0
    bad_seq: int = 0
    msg_tx: int = 0
    rolling_count_echo: int = 0
    e2e_errors: int = 0  # HOST_VEH_STATE structures rejected by their CRC or counter (D5)
    counter_gaps: int = 0  # DASP counter steps other than +1 (D1), not wrapped like bad_seq
    bad_hdr_total: int = 0  # bad_hdr, not wrapped
    veh_state_stale: int = 0  # HOST_VEH_STATE silent > 3 periods in Running Vision (§7.1.2.2)
    mesp_requests: int = 0
    # MESP replies the host waits for in vain (M6: no reply within the deadline is a timeout):
    # dropped (--drop-reply, or still delayed when the EyeQ reset) or sent past the deadline
    mesp_replies_dropped: int = 0
    mesp_replies_late: int = 0
    received: Counter[str] = field(default_factory=Counter)
    rejected_values: int = 0  # vehicle signals not valid, not finite or outside the seed range
    edr_triggers: list[dict[str, Any]] = field(default_factory=list)
    calibration_events: list[tuple[int, int]] = field(default_factory=list)  # (stage, ret)
    boots: int = 0
    self_resets: int = 0  # resets of its own (SimConfig.reset_at), no host asked for them
    vision_switches: int = 0  # accepted Switch EyeQ Application to Vision: a reset (L10)
    sent: Counter[str] = field(default_factory=Counter)


class MespFunctions:
    """The MESP handlers of the simulated EyeQ, on the state it keeps (set in its ``__init__``)."""

    sw: str
    now: float
    api_version: tuple[int, int]
    sw_version: tuple[int, int]
    main_state: int
    sub_state: int
    fatal_error: int
    conn: TransportConnection
    eeprom: bytearray
    flash: FlashImage
    counters: SimCounters
    _expected_0x84_no_crc: bytes | None
    _rx_e2e: E2EState
    _last_veh: float | None
    _init_ok: bool
    _cal_started: float | None
    _next_dasp: dict[str, float]

    def _get_state(self, params: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        return 0, {"mainState": self.main_state, "subState": self.sub_state}

    def _get_versions(self, params: dict[str, Any]) -> tuple[int, dict[str, Any]]:
        return 0, {"apiVersionMajor": self.api_version[0],
                   "apiVersionMinor": self.api_version[1],
                   "eyeqSwVersionMajor": self.sw_version[0],
                   "eyeqSwVersionMinor": self.sw_version[1]}

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
        # the application restarts: it judges the host's E2E rolling counters afresh, as the
        # host's restarted bring-up starts them afresh (found by tools/soak_live.py)
        self._rx_e2e = E2EState()
        self._last_veh = None
        self._init_ok = False
        self._cal_started = None
        self._next_dasp.clear()
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
            return self._cal_result(stage, RET_BAD_PARAMETERS, request)
        if request["ct_type"] != msg.ct_type:
            return self._cal_result(stage, RET_BAD_PARAMETERS, request)
        if msg.codec is not None and (len(params) != msg.codec.length or msg.check(params)):
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
