"""The conformance vocabulary every part shares, at the bottom of the package: a case as data,
the MESP tags our tester reserves for its raw probes, and the load gauge's stall threshold.

Both wings read it — ``play`` (the scripts that send the probes) and ``judges`` (which look for
their replies) — as do the table of cases, the load gauge and the suite above them; it imports
nothing of the conformance package itself."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

ALL_SESSIONS = "*"  # Case.session: the host case is judged on the trace of every host session
TIMING, CONTENT = "timing", "content"  # Case.rule


@dataclass(frozen=True)
class Case:
    """One case: ID, title, seed 004 section, requirement ID (MAPC-…), decisions, group, which
    implementation under test it applies to, its judge, the session whose trace it reads, the
    script steps it needs, and whether its rule is one of timing or of content."""

    id: str
    title: str
    section: str
    requirement: str | None
    decision: str | None
    group: str
    duts: tuple[str, ...]
    judge: Callable[..., Any]
    session: str = "main"  # the host suite: normal | eeprom_bad | boot_fail | *
    needs: tuple[str, ...] = ()  # script steps: early_init, mesp, link, flows
    # TIMING: the rule is a deadline, a period or a spacing, so a stall of our own loop that
    # overlaps a measurement may explain its miss (load.py); CONTENT: counters, lengths, CRCs,
    # tags, padding, order: no stall of ours ever excuses a fail
    rule: str = "content"

    def session_for(self, dut: str) -> str:
        if dut == "eyeq":
            return "main"
        return "normal" if self.session == "main" else self.session


# MESP tag counters reserved for raw probes (M1: 0..63); our host's own client never has a
# request of the same service/function outstanding while one of these is in flight. The host
# script sends them (play.host); the judges look for their replies (judges.app, judges.link).
TAG_EARLY_INIT, TAG_BAD_SWITCH, TAG_BAD_HASH, TAG_UNKNOWN_FN, TAG_UNKNOWN_SVC = 63, 62, 61, 60, 59
TAG_LIMIT, TAG_CONTROL, TAG_GAP, TAG_SILENCE, TAG_DUP = 58, 57, 56, 55, 54
# (tag counter, function) of each raw probe request -> the case that judges its answer
PROBE_CASE = {(TAG_EARLY_INIT, "EventCalibrationTool"): "FLOW-PENDING",
              (TAG_BAD_SWITCH, "SwitchEyeQApplication"): "MESP-BADPARAM",
              (TAG_BAD_HASH, "ComputeHash"): "MESP-BADPARAM",
              (TAG_LIMIT, "GetEyeQVersions"): "TP-LIMIT",
              (TAG_CONTROL, "GetEyeQVersions"): "TP-ABORT",
              (TAG_GAP, "GetEyeQVersions"): "TP-ABORT",
              (TAG_SILENCE, "GetEyeQVersions"): "TP-ABORT",
              (TAG_DUP, "GetEyeQExtendedState"): "LINK-DUP"}

# the load gauge (load.py): seconds beyond the session loop's SLICE (play.session) before a
# late loop turn counts as a stall of ours
STALL_MIN = 0.002
