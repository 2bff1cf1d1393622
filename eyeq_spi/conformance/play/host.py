"""We play the host against an EyeQ under test: our :class:`HostEmulator` brings it up, and the
script adds the probes the cases judge, each step only when a selected case needs it
(docs/conformance.md, "Sessions"). Every probe leaves a mark in the trace."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from eyeq_spi.catalog.link import link_spec
from eyeq_spi.codec.init_params import init_message
from eyeq_spi.conformance.model import (
    TAG_BAD_HASH,
    TAG_BAD_SWITCH,
    TAG_CONTROL,
    TAG_DUP,
    TAG_EARLY_INIT,
    TAG_GAP,
    TAG_LIMIT,
    TAG_SILENCE,
    TAG_UNKNOWN_FN,
    TAG_UNKNOWN_SVC,
)
from eyeq_spi.conformance.play.session import PROBE_LINK_TAG, Session
from eyeq_spi.errors import LocalProtocolError
from eyeq_spi.host.host import HostEmulator
from eyeq_spi.host.machine import HostState
from eyeq_spi.transport.segment import segment

_T = link_spec()["transport"]

EDR_EXAMPLE = {"edr_type": 6, "edr_policy": 1, "edr_function": 4, "edr_params_num": 1,
               "params": b"\x01"}  # M4, the seed's "Trigger LB1" example


@dataclass
class HostPlan:
    """Timings of the script. The defaults suit a real EyeQ; ``--builtin`` shortens them."""

    bring_up_timeout: float = 15.0
    hold_veh: float = 0.3  # HOST_VEH_STATE_MSG held back after 0x92 (Running Vision must wait)
    steady: float = 1.5  # seconds of Running Vision watched for rates
    mode_timeout: float = 10.0  # TAC/SPC results, DV entry, back to vision
    mode_hold: float = 0.8  # seconds in TAC/SPC watched for their rates


class TesterHost(HostEmulator):
    """Our host emulator with one change for the tester: HOST_VEH_STATE_MSG starts ``hold``
    seconds after the init messages instead of at once."""

    def __init__(self, *args: Any, hold: float = 0.0, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.hold = hold
        self._hold_until = float("-inf")

    def entry_start_vehicle_state(self, now: float) -> None:
        self._hold_until = now + self.hold
        super().entry_start_vehicle_state(now)

    def _send_veh_state(self, now: float) -> None:
        if now >= self._hold_until:
            super()._send_veh_state(now)


class HostScript:
    def __init__(self, session: Session, host: TesterHost, plan: HostPlan,
                 wanted: set[str]) -> None:
        self.session, self.host, self.plan, self.wanted = session, host, plan, wanted
        self.trace = session.trace
        self.codec = host.mesp.codec

    def raw(self, function: str, tag: int, params: dict[str, Any] | None = None) -> bytes:
        return self.codec.encode_request(function, tag, params or {})

    def send_raw(self, label: str, message: bytes) -> None:
        self.trace.mark(self.session.now, label, tag=message[4], service=message[0],
                        function=message[3])
        self.host.conn.send(message, self.session.now)

    def link_payloads(self, label: str, payloads: list[bytes], *, drop: int | None = None
                      ) -> None:
        """Queue transport payloads straight on our link (our NUMs, our pacing)."""
        for index, payload in enumerate(payloads):
            how = "drop" if index == drop else "label"
            self.session.shim.watch(payload, f"{label}#{index}", how)
            tag = PROBE_LINK_TAG + len(self.trace.marks)
            self.host.conn.link.send(payload, tag, self.session.now)
        self.trace.mark(self.session.now, label, frames=len(payloads))

    def seen_boot(self) -> bool:
        return bool(self.host.boot_info)  # cheap: no decoding of the trace while we wait

    # -- the script ------------------------------------------------------------------------
    def run(self) -> None:
        session, host, plan = self.session, self.host, self.plan
        self.trace.mark(session.now, "start")
        host.start(session.now)
        if session.wait(self.seen_boot, 5.0) and "early_init" in self.wanted:
            params = init_message(0x92, host.sw, host.codec.cat)
            assert params.codec is not None
            body = params.codec.encode({})
            self.send_raw("early_init", self.raw("EventCalibrationTool", TAG_EARLY_INIT, {
                "ct_type": params.ct_type, "ct_stage": 0x92,
                "ct_version": params.ct_version(body), "params": body}))
        running = session.wait(lambda: host.state in (HostState.RUNNING_VISION, HostState.FAILED),
                               plan.bring_up_timeout)
        if not running or host.state is not HostState.RUNNING_VISION:
            self.trace.mark(session.now, "bring_up_failed", state=host.state.value,
                            problem=host.problem)
            return
        self.trace.mark(session.now, "running")
        session.run(plan.steady)
        self.trace.mark(session.now, "steady_end")
        if "mesp" in self.wanted:
            self.mesp_probes()
        if "link" in self.wanted:
            self.link_probes()
        if "flows" in self.wanted:
            for mode in ("TAC", "SPC", "DV"):
                if not self.mode_round_trip(mode):
                    break

    def mesp_probes(self) -> None:
        session, host = self.session, self.host
        requests: list[tuple[str, dict[str, Any]]] = [
            ("GetEyeQExtendedState", {}), ("GetEyeQVersions", {}),
            ("FFSReadFile", {"filename": "/mesp/eeprom.data1"}),
            ("ComputeHash", {"hashType": 1, "datasetType": 0, "start": 0, "size": 4096}),
            ("ComputeHash", {"hashType": 0, "datasetType": 0, "start": 0, "size": 4096}),
            ("SendParamsToCalibrationTool", EDR_EXAMPLE),
        ]
        for fn, params in requests:
            host.mesp.request(fn, params, now=session.now)
            session.run(0.06)
        self.send_raw("bad_params", self.raw("SwitchEyeQApplication", TAG_BAD_SWITCH,
                                             {"applicationId": 0x7E}))
        session.run(0.06)
        hash_req = self.raw("ComputeHash", TAG_BAD_HASH,
                            {"hashType": 1, "datasetType": 0, "start": 0, "size": 16})
        self.send_raw("bad_params", hash_req[:-6])  # truncated: start and size cut short
        session.run(0.06)
        self.send_raw("unknown_function", bytes((0x05, 0x5E, 0x05, 0x7F, TAG_UNKNOWN_FN)))
        session.run(0.06)
        self.send_raw("unknown_service", bytes((0x09, 0x5E, 0x09, 0x01, TAG_UNKNOWN_SVC)))
        session.run(0.1)

    def link_probes(self) -> None:
        session, host, shim, trace = self.session, self.host, self.session.shim, self.trace
        link = host.conn.link
        t0 = session.now
        session.nak_probes(link)
        dup = self.raw("GetEyeQExtendedState", TAG_DUP)
        shim.watch(segment(dup, 0)[0], "dup", "duplicate")
        self.send_raw("dup_request", dup)
        session.run(0.1)
        limit = int(_T["receive_limit"][trace.dut])
        junk = bytes(range(256)) * 40
        over = self.raw("GetEyeQVersions", TAG_LIMIT) + junk
        self.link_payloads("limit_over", segment(over[: limit + 1], 0xC1)[:1])
        session.run(0.05)
        self.link_payloads("limit_at", segment(over[:limit], 0xC2))
        session.run(0.15)
        for label, tag, tid, drop in (("abort_control", TAG_CONTROL, 0xC3, None),
                                      ("abort_gap", TAG_GAP, 0xC4, 1)):
            msg = (self.raw("GetEyeQVersions", tag) + junk)[:300]
            self.link_payloads(label, segment(msg, tid), drop=drop)
            session.run(0.2)
        msg = (self.raw("GetEyeQVersions", TAG_SILENCE) + junk)[:300]
        parts = segment(msg, 0xC5)
        self.link_payloads("abort_silence", parts[:2])
        session.run(0.04)  # > 25 ms of silence (T6)
        self.link_payloads("abort_silence_tail", parts[2:])
        session.run(0.2)
        trace.fault(t0, session.now, "probes")
        session.ack_blackout(0.1, 0.2)  # 100 ms: an 18 Hz cycle
        # our driver reset: our NUMs from 0 again (L4, L6); our receive window is kept
        t2 = session.now
        link.reset(tx_num=0, expected=link.expected_num)
        trace.restart_passive(trace.our_dir)
        trace.mark(t2, "our_reset")
        session.run(0.15)
        host.mesp.request("GetEyeQExtendedState", now=session.now)
        trace.mark(session.now, "after_reset_request")
        session.run(0.2)
        trace.fault(t2, session.now, "our_reset")

    def mode_round_trip(self, mode: str) -> bool:
        session, host, plan, trace = self.session, self.host, self.plan, self.trace
        target = {"TAC": HostState.RUNNING_TAC, "SPC": HostState.RUNNING_SPC,
                  "DV": HostState.DV}[mode]
        t0 = session.now
        trace.mark(t0, "switch", mode=mode)
        # our host may be bringing the DUT up again (it took something for a reset): wait
        settled = (HostState.RUNNING_VISION, HostState.FAILED)
        session.wait(lambda: host.state in settled, plan.mode_timeout)
        try:
            host.switch_mode(mode, session.now)
        except LocalProtocolError as exc:
            trace.mark(session.now, "mode_done", mode=mode, ok=False, entered=session.now,
                       state=host.state.value, result={}, problem=f"not switched: {exc}")
            return False

        def reached() -> bool:  # DV, or TAC/SPC with their results
            return host.state is HostState.FAILED or (host.state is target and (
                mode == "DV" or host.calibration_result is not None))

        ok = session.wait(reached, plan.mode_timeout) and host.state is not HostState.FAILED
        entered = session.now
        if ok:
            session.run(plan.mode_hold if mode != "DV" else 0.2)
        result = dict(host.calibration_result or {})
        trace.mark(session.now, "mode_done", mode=mode, ok=ok, entered=entered,
                   state=host.state.value, result=result, problem=host.problem)
        if not ok:
            return False
        host.switch_mode("VISION", session.now)
        back = session.wait(lambda: host.state in settled, plan.mode_timeout)
        back = back and host.state is HostState.RUNNING_VISION
        trace.mark(session.now, "mode_back", mode=mode, ok=back, state=host.state.value)
        if back:
            session.run(0.2)
        return back
