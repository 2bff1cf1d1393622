"""Lossy-channel soak: the host emulator and the simulated EyeQ over a memory pair whose fault
hook is a :class:`FaultyChannel` in each direction, in virtual time.

Accounting (every fault on the channel X -> Y is seen by Y's link counters; deltas are taken
from the moment the faults are switched on, and the channels run clean for ``settle`` seconds at
the end so that every held or skipped frame is followed by a clean one). ``late`` below is the
number of DATA frames held back and overtaken by the next DATA frame; ``F`` is the number of
valid DATA frames Y's transport NAKed 0x011 because an earlier loss left the wrong transfer open
(T6 ``wrong_id``): a consequence of a fault, not a fault of its own.

=======================  ===================================================================
counter of Y             rule
=======================  ===================================================================
badLengthTransfers       = truncated transfers (L8)
dataCRCErrorCounter      = flipped transfers whose flips the L3 CRC covers: any flip in a DATA
                         frame, a flip in bytes 0..5 of an ACK/NAK (their pad is not covered)
duplicateFrames          = duplicated DATA frames (L6a: byte-identical, accepted before)
resynchronisations       = 0: no fault of one channel looks like a peer reset (L6a)
skipped - late           = DATA frames dropped, truncated or flipped, + F. Exact: when the frame
                         that overtook a held first frame is NAKed 0x011, the held one is no
                         longer late (accepted in window) and the NAKed one is skipped instead
lateFrames               in [late - F, late]: NAKed 0x001 (L6a), see the line above
unexpectedAckCounter     at least the duplicated ACK/NAKs into Y; at most that plus the
                         reordered ACK/NAKs into Y plus the DATA frames of Y duplicated or
                         reordered on the way out (the peer ACKs a copy again; a held frame's
                         ACK or NAK comes after Y gave up on it) plus Y's frames with a flip in
                         the header (the peer NAKs the NUM it read, L5, or NAKs an ACK whose D
                         it no longer sees). A held transfer is late only if the next one came
                         after ``ackTimeout``, and a second ACK can itself be lost.
=======================  ===================================================================
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from eyeq_spi.emulator import Emulation
from eyeq_spi.faults.channel import FaultProfile, FaultyChannel
from eyeq_spi.faults.rig import Scene, adapters, rig
from eyeq_spi.faults.taps import MessageLedger, tap
from eyeq_spi.host.machine import HostState
from eyeq_spi.link.counters import SpiDiagnosticInfo

COUNTERS = ("badLengthTransfers", "dataCRCErrorCounter", "duplicateFrames",
            "sequenceErrorCounter", "lateFrames", "skippedFrames", "resynchronisations",
            "unexpectedAckCounter", "framesReceived", "formatNaks")
EXACT = ("badLengthTransfers", "dataCRCErrorCounter", "duplicateFrames", "resynchronisations",
         "skippedMinusLate")
BOUNDED = ("lateFrames", "unexpectedAckCounter")
FORMAT_ERROR = 0x011


@dataclass(frozen=True)
class SoakConfig:
    profile: FaultProfile = field(default_factory=FaultProfile)
    seed: int = 1
    duration: float = 10.0  # virtual seconds with faults on
    settle: float = 0.1  # clean seconds at the end
    faults_from_start: bool = False  # False: switch faults on once Running Vision is reached
    bring_up_limit: float = 10.0  # virtual seconds allowed to reach Running Vision
    sw: str | None = None
    scene: Scene = field(default_factory=Scene)


@dataclass
class Accounting:
    """One receiving side: what the channel into it injected, what its counters say."""

    injected: dict[str, int]
    expected: dict[str, int]
    observed: dict[str, int]
    bounds: dict[str, tuple[int, int]]

    def mismatches(self, names: tuple[str, ...] = EXACT) -> dict[str, tuple[int, int]]:
        return {n: (self.expected[n], self.observed[n]) for n in names
                if self.expected[n] != self.observed[n]}

    def out_of_bounds(self) -> dict[str, tuple[int, tuple[int, int]]]:
        return {n: (self.observed[n], b) for n, b in self.bounds.items()
                if not b[0] <= self.observed[n] <= b[1]}

    @property
    def ok(self) -> bool:
        return not self.mismatches() and not self.out_of_bounds()


@dataclass
class SoakReport:
    config: dict[str, Any]
    virtual_s: float
    wall_s: float
    reached_vision_at: float | None
    held: bool  # reached Running Vision and never left it
    final_state: str
    frames: dict[str, int]  # transfers offered per direction
    messages: dict[str, dict[str, int]]
    accounting: dict[str, Accounting]  # by receiving side: "eyeq", "host"
    host: dict[str, Any]

    @property
    def corrupted(self) -> int:
        return sum(m["corrupted"] for m in self.messages.values())

    @property
    def injected_total(self) -> int:
        return sum(sum(a.injected.values()) for a in self.accounting.values())

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["corrupted"] = self.corrupted
        out["injected_total"] = self.injected_total
        return out


def _counts(counters: SpiDiagnosticInfo) -> dict[str, int]:
    out = {n: int(getattr(counters, n)) for n in COUNTERS if n != "formatNaks"}
    out["formatNaks"] = int(counters.naksSent.get(FORMAT_ERROR, 0))
    return out


def account(into: FaultyChannel, out_of: FaultyChannel, before: dict[str, int],
            after: dict[str, int]) -> Accounting:
    """The table of the module docstring, for the side fed by ``into`` that sends through
    ``out_of``."""
    ch = into
    observed = {n: after[n] - before[n] for n in COUNTERS}
    observed["skippedMinusLate"] = observed["skippedFrames"] - observed["lateFrames"]
    format_naks = observed["formatNaks"]
    late = ch.count("reorder", "DATA", after="DATA")
    lost = ch.count("drop", "DATA") + ch.count("truncate", "DATA") + ch.count("flip", "DATA")
    control_dups = ch.count("duplicate", "ACK") + ch.count("duplicate", "NAK")
    control_late = (ch.count("reorder", "ACK") + ch.count("reorder", "NAK")
                    + out_of.count("duplicate", "DATA") + out_of.count("reorder", "DATA")
                    + out_of.header_flips())
    expected = {
        "badLengthTransfers": ch.count("truncate"),
        "dataCRCErrorCounter": ch.count("flip", crc_covered=True),
        "duplicateFrames": ch.count("duplicate", "DATA"),
        "resynchronisations": 0,
        "skippedMinusLate": lost + format_naks,
        "lateFrames": late,
        "unexpectedAckCounter": control_dups,
    }
    bounds = {"lateFrames": (max(0, late - format_naks), late),
              "unexpectedAckCounter": (control_dups, control_dups + control_late)}
    return Accounting(dict(ch.stats.injected), expected, observed, bounds)


def run_soak(config: SoakConfig | None = None) -> SoakReport:
    cfg = config or SoakConfig()
    emu = rig(seed=cfg.seed, sw=cfg.sw, scene=cfg.scene)
    host_end, sim_end = adapters(emu)
    h2e = FaultyChannel(cfg.profile, cfg.seed * 2 + 0)
    e2h = FaultyChannel(cfg.profile, cfg.seed * 2 + 1)
    ledgers = {"host_to_eyeq": tap(emu.host.conn, emu.sim.conn),
               "eyeq_to_host": tap(emu.sim.conn, emu.host.conn)}
    host_end.mangle, sim_end.mangle = h2e, e2h

    def in_vision() -> bool:
        return emu.host.state is HostState.RUNNING_VISION

    def snapshot() -> dict[str, dict[str, int]]:
        return {"eyeq": _counts(emu.sim.conn.link.counters),
                "host": _counts(emu.host.conn.link.counters)}

    h2e.enabled = e2h.enabled = cfg.faults_from_start
    before = snapshot()
    emu.run_for(cfg.bring_up_limit, stop=in_vision)
    reached = emu.runner.now if in_vision() else None
    if not cfg.faults_from_start:
        h2e.enabled = e2h.enabled = True
        before = snapshot()
    if reached is not None:
        emu.run_for(cfg.duration)
    h2e.enabled = e2h.enabled = False
    emu.run_for(cfg.settle)
    after = snapshot()
    return SoakReport(
        config={"profile": asdict(cfg.profile), "seed": cfg.seed, "duration": cfg.duration,
                "faults_from_start": cfg.faults_from_start, "sw": emu.host.sw},
        virtual_s=round(emu.runner.now, 6), wall_s=round(emu.runner.wall_s, 3),
        reached_vision_at=reached,
        held=reached is not None and not emu.vision.left and in_vision(),
        final_state=emu.host.state.value,
        frames={"host_to_eyeq": h2e.stats.transfers, "eyeq_to_host": e2h.stats.transfers},
        messages={k: _ledger_figures(v) for k, v in ledgers.items()},
        accounting={"eyeq": account(h2e, e2h, before["eyeq"], after["eyeq"]),
                    "host": account(e2h, h2e, before["host"], after["host"])},
        host=_host_figures(emu),
    )


def _ledger_figures(book: MessageLedger) -> dict[str, int]:
    return {"sent": book.messages_sent, "delivered": book.messages_delivered,
            "corrupted": book.bad_deliveries}


def _host_figures(emu: Emulation) -> dict[str, Any]:
    host = emu.host
    counters, mesp = host.counters, host.mesp.counters
    return {"eyeq_resets": counters.eyeq_resets, "boot_failures": counters.boot_failures,
            "mesp_retries": mesp.retries, "mesp_failures": mesp.failures,
            "e2e_errors": counters.e2e_errors, "dasp_counter_gaps": counters.dasp_counter_gaps,
            "stale_events": sum(host.counters.stale_events.values()),
            "transport_aborts": sum(host.conn.counters.transferAborts.values()),
            "problem": host.problem, "transitions": [t.dst.value for t in host.transitions]}
