"""The conformance vocabulary both wings share (``play`` and ``judges``): a case as data, the MESP
tags reserved for our raw probes, and the load gauge's stall threshold."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

ALL_SESSIONS = "*"  # Case.session: the host case is judged on the trace of every host session
TIMING, CONTENT = "timing", "content"  # Case.rule


@dataclass(frozen=True)
class Case:
    """One case: its references (seed 004 section, MAPC requirement, decisions), the sides it
    applies to, its judge, the session it reads, the script steps it needs, its kind of rule."""

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
    rule: str = CONTENT  # TIMING (a stall of ours may excuse a miss, load.py) or CONTENT

    def session_for(self, dut: str) -> str:
        if dut == "eyeq":
            return "main"
        return "normal" if self.session == "main" else self.session


# MESP tag counters reserved for raw probes (M1: 0..63), sent by play.host, judged by judges
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

# seconds beyond the session loop's SLICE (play.session) before a late turn is a stall of ours
STALL_MIN = 0.002
