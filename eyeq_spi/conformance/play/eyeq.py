"""We play the EyeQ against a host under test: our :class:`SimulatedEyeQ` with the faults each
session needs, one session per ignition cycle: ``normal``, ``eeprom_bad`` and ``boot_fail``
(docs/conformance.md, "Sessions"). A reset is a reset-line pulse (``--builtin``) or, for a host
without one, Switch EyeQ Application to vision (the project's soft reset)."""

from __future__ import annotations

from dataclasses import dataclass

from eyeq_spi.catalog.link import link_spec
from eyeq_spi.codec.message import is_mesp
from eyeq_spi.conformance.play.session import PROBE_LINK_TAG, Session
from eyeq_spi.conformance.trace import Trace
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.sim.eyeq import SimulatedEyeQ
from eyeq_spi.transport.segment import segment

_T = link_spec()["transport"]
SWITCH = (0x05, 0x05)
VERSIONS = (0x05, 0x04)
REARM_WITHIN = 1.5  # s: a reset this soon after a withheld reply withholds the next one
APP_VISION = 0x01
STALE_STREAM = "EYEQ_VIS_SRP_MSG"


@dataclass
class EyeqPlan:
    bring_up_timeout: float = 15.0
    steady: float = 1.5
    stale_for: float = 0.6
    after_reset: float = 4.0  # at most, for the host to bring us up again after our reset
    after_running: float = 0.5  # watched once we are back in Running Vision
    boot_fail_watch: float = 6.0
    eeprom_watch: float = 1.5  # HOST-EEPROM-BAD needs >= 1 s of it (judges.flow.QUIET_FOR)


class TesterEyeQ(SimulatedEyeQ):
    """Our simulated EyeQ, recording the host's requests and its resets: reset-line pulses and
    soft resets."""

    def __init__(self, config: SimConfig, trace: Trace) -> None:
        super().__init__(config)
        self.trace = trace
        self.reset_times: list[float] = []
        self.requests: list[tuple[float, int, int, int]] = []  # (time, service, function, tag)
        # (service, function) of requests whose first occurrence we leave unanswered (M6)
        self.withhold: set[tuple[int, int]] = set()
        self._withheld: list[tuple[float, tuple[int, int]]] = []

    def _reset_asked(self, now: float, label: str) -> None:
        """A reset right after a withheld reply leaves nothing to judge (the host's requests
        start over): withhold the next one instead."""
        self.reset_times.append(now)
        self.trace.mark(now, label)
        for due, key in self._withheld:
            if now - due < REARM_WITHIN:
                self.withhold.add(key)

    def power_up(self, now: float) -> None:
        """A boot: after the first, our receiver and the trace's receiver of the host's frames
        learn the host's numbering again (L10, L10a)."""
        again = self.powered
        super().power_up(now)
        if again:
            self.trace.restart_passive(self.trace.dut_dir)

    def reset_line(self, now: float) -> None:
        """The host pulled our reset line: it restarts its own SPI driver too."""
        self._reset_asked(now, "reset_line")
        self.trace.restart_passive(self.trace.our_dir)
        self.power_up(now)

    def _on_message(self, data: bytes, now: float) -> None:
        key = (data[0], data[3]) if is_mesp(data) and not data[4] & 0x80 else None
        if key is not None:
            self.requests.append((now, data[0], data[3], data[4]))
        if key is not None and key in self.withhold:
            # the link ACKed the request but its reply never leaves: the host must retry (M6)
            self.withhold.discard(key)
            self._withheld.append((now, key))
            self.trace.mark(now, "reply_withheld", service=data[0], function=data[3],
                            tag=data[4] & 0x3F)
            return
        if key == SWITCH and data[5:6] == bytes([APP_VISION]):
            # the host restarts its bring-up and its counters; our link starts afresh (L10)
            self._reset_asked(now, "soft_reset")
            if not self.app_running:
                self.trace.restart_passive(self.trace.our_dir)
                self.power_up(now)  # a soft reset while booting: boot again
                return
            self.trace.restart_passive(self.trace.dut_dir)
        super()._on_message(data, now)


def tester_config(session: str, sw: str | None, fast: bool) -> SimConfig:
    cfg = SimConfig(sw=sw, objects=1, signs=1, light_spots=1, app_start_delay=0.3)
    if fast:
        cfg.tac_duration = 0.3
    if session == "eeprom_bad":
        cfg.corrupt_eeprom_crc = True
        cfg.fatal_error = 22
    elif session == "boot_fail":
        cfg.boot_failures = 1_000_000
        cfg.boot_test_failures = 0x0002
    return cfg


class EyeqScript:
    def __init__(self, session: Session, eyeq: TesterEyeQ, plan: EyeqPlan, kind: str,
                 wanted: set[str]) -> None:
        self.session, self.eyeq, self.plan = session, eyeq, plan
        self.kind, self.wanted = kind, wanted
        self.trace = session.trace

    def host_running(self) -> bool:
        return self.eyeq.main_state == 0x02

    def run(self) -> None:
        session, eyeq, trace = self.session, self.eyeq, self.trace
        trace.mark(session.now, "start", session=self.kind)
        eyeq.power_up(session.now)
        if self.kind == "normal":
            self.normal()
        elif self.kind == "eeprom_bad":
            session.run(0.3)
            trace.mark(session.now, "fatal22", forced=True)
            session.wait(lambda: any(r[1:3] == (0x03, 0x02) for r in eyeq.requests), 5.0)
            session.run(0.05)
            trace.mark(session.now, "eeprom_served")
            session.run(self.plan.eeprom_watch)
        else:
            session.run(self.plan.boot_fail_watch)
        trace.mark(session.now, "resets", times=list(eyeq.reset_times))

    def normal(self) -> None:
        session, eyeq, trace, plan = self.session, self.eyeq, self.trace, self.plan
        eyeq.withhold.add(VERSIONS)  # HOST-RETRY (M6)
        # an unmatched reply while we boot (M1): claims Pending Vision with a tag never used
        if session.wait(lambda: eyeq.main_state == 0x03, 5.0):
            polls = [r for r in eyeq.requests if r[1:3] == (0x05, 0x03)]
            tag = ((polls[-1][3] + 32) & 0x3F) if polls else 0x2A
            bogus = eyeq.server.codec.encode_reply("GetEyeQExtendedState", tag, 0,
                                                   {"mainState": 0x01, "subState": 0x92})
            eyeq.conn.send(bogus, session.now)
            trace.mark(session.now, "unmatched_reply", tag=tag)
        if not session.wait(self.host_running, plan.bring_up_timeout):
            trace.mark(session.now, "bring_up_failed")
            return
        trace.mark(session.now, "running")
        session.run(plan.steady)
        trace.mark(session.now, "steady_end")
        if "link" in self.wanted:
            self.link_probes()
        at = session.now
        eyeq.config.stop_dasp[STALE_STREAM] = at
        trace.mark(at, "stale_start", stream=STALE_STREAM)
        session.run(plan.stale_for)
        detected = None
        if self.session.dut is not None:  # --builtin: our host's public view
            detected = STALE_STREAM in self.session.dut.stale_streams
        trace.mark(session.now, "stale_end", stream=STALE_STREAM, detected=detected)
        del eyeq.config.stop_dasp[STALE_STREAM]
        session.run(0.3)
        at = session.now
        trace.mark(at, "our_reset")
        eyeq.power_up(at)
        trace.restart_passive(trace.our_dir)
        # HOST-EYEQ-RESET: Running Vision again needs both 0x92 and HOST_VEH_STATE_MSG
        if session.wait(self.host_running, plan.after_reset):
            session.run(plan.after_running)
        trace.mark(session.now, "after_reset_end")

    def link_probes(self) -> None:
        session, shim, trace = self.session, self.session.shim, self.trace
        link = self.eyeq.conn.link
        t0 = session.now
        session.nak_probes(link)
        # a stale MESP reply (tag never used): harmless to a host, single frame, duplicated
        stale = self.eyeq.server.codec.encode_reply("GetEyeQVersions", 0x3F, 0, {
            "apiVersionMajor": 0, "apiVersionMinor": 0, "eyeqSwVersionMajor": 0,
            "eyeqSwVersionMinor": 0})
        first = segment(stale, 0)[0]
        shim.watch(first, "dup", "duplicate")
        link.send(first, PROBE_LINK_TAG, session.now)
        trace.mark(session.now, "dup_request")
        session.run(0.05)
        limit = int(_T["receive_limit"][trace.dut])
        # a first frame announcing one byte more than the host may receive (T6: NAK 0x011)
        over = bytes([_T["types"]["first"], 0xC1]) + (limit + 1).to_bytes(4, "little") \
            + bytes(_T["first_chunk"])
        shim.watch(over, "limit_over#0")
        link.send(over, PROBE_LINK_TAG + 1, session.now)
        trace.mark(session.now, "limit_over")
        session.run(0.05)
        trace.fault(t0, session.now, "probes")
        session.ack_blackout(0.06, 0.2)

