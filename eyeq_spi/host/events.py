"""What the EyeQ's answers mean to the host's state table (``machine.py``): the event a Get
Extended State reply or a 0x41 EYEQ_DIAGNOSTIC_MSG starts in each state (seed 004 §6 message
flow, §7.1.1.1.4, §7.1.3), pure functions of the state and the message's fields; and the
polling of Get Extended State in the states that wait for a mode (:class:`StatePoll`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from eyeq_spi.catalog.bringup import (
    FATAL_INTRINSIC,
    PENDING,
    PENDING_VISION,
    RUNNING_DV,
    RUNNING_SPC,
    RUNNING_TAC,
    RUNNING_VISION,
)
from eyeq_spi.host.config import PENDING_OF
from eyeq_spi.host.machine import HostEvent, HostState

POLLING = frozenset({HostState.WAIT_PENDING, HostState.WAIT_RUNNING,
                     HostState.WAIT_MODE_PENDING, HostState.WAIT_MODE_RUNNING})
"""The states that poll Get Extended State until the EyeQ reaches the mode they wait for."""

VERSION_FIELDS = ("apiVersionMajor", "apiVersionMinor", "eyeqSwVersionMajor",
                  "eyeqSwVersionMinor")
"""What the host keeps of a Get EyeQ Versions reply (``HostEmulator.versions``, the NVM)."""

_MODE_RUNNING = {RUNNING_TAC: HostEvent.RUNNING_TAC, RUNNING_SPC: HostEvent.RUNNING_SPC}


def state_reply_event(state: HostState, target_mode: str, main: int,
                      sub: int) -> HostEvent | None:
    """The event a Get Extended State reply (``mainState``, ``subState``) starts in ``state``
    while the host heads for ``target_mode``, or None (it polls on)."""
    if state is HostState.WAIT_PENDING:
        return HostEvent.PENDING_VISION if (main, sub) == (PENDING, PENDING_VISION) else None
    if state is HostState.WAIT_RUNNING:
        return HostEvent.RUNNING_VISION if main == RUNNING_VISION else None
    if state is HostState.WAIT_MODE_PENDING:
        if target_mode == "DV" and main == RUNNING_DV:
            return HostEvent.MODE_DV
        if main == PENDING and sub == PENDING_OF.get(target_mode):
            if target_mode == "VISION":
                return HostEvent.MODE_VISION_PENDING
            return HostEvent.MODE_PENDING
        return None
    if state is HostState.WAIT_MODE_RUNNING:
        return _MODE_RUNNING.get(main)
    return None


def diag_event(state: HostState, fields: Mapping[str, Any], reported_before: bool) -> str | None:
    """What a good 0x41 starts in ``state``: ``"fatal_22"`` (intrinsic calibration mismatch
    before vision, §7.1.3), ``"fatal"``, ``"went_back"`` (a running EyeQ reports boot or
    pending again: it reset), or None (it is only kept). ``reported_before``: an earlier 0x41
    reported a Main_State."""
    main, fatal = fields["Main_State"], fields["Fatal_Error"]
    if fatal == FATAL_INTRINSIC and state in (HostState.WAIT_PENDING, HostState.INIT,
                                              HostState.WAIT_RUNNING):
        return "fatal_22"
    if fatal and state not in (HostState.FATAL, HostState.READ_EEPROM, HostState.FAILED,
                               HostState.POWER_UP):
        return "fatal"
    # A running EyeQ never reports boot or pending again without a reset. Compare with the
    # mode, not with the previous 0x41: the host can reach Running Vision by a Get State
    # reply before any 0x41 has reported it (found by the reset campaign, faults/resets.py).
    if (state in (HostState.RUNNING_VISION, HostState.RUNNING_TAC, HostState.RUNNING_SPC)
            and main in (0, PENDING) and reported_before):
        return "went_back"
    return None


class StatePoll:
    """Get Extended State, asked at once on entering a waiting state and again
    ``interval`` after each answer (or failure) while the host is in one of the
    :data:`POLLING` states; one request at a time."""

    def __init__(self, interval: float) -> None:
        self.interval = interval
        self.next_due: float | None = None
        self.busy = False  # a request is on its way

    def start(self, now: float) -> None:
        self.next_due = now

    def stop(self) -> None:
        self.next_due, self.busy = None, False

    def due(self, now: float) -> bool:
        return self.next_due is not None and now >= self.next_due and not self.busy

    def asked(self) -> None:
        self.next_due, self.busy = None, True

    def answered(self, state: HostState, now: float) -> None:
        """The request was answered or failed; in ``state`` (after whatever the answer
        started) the host polls on unless it already has a request due."""
        self.busy = False
        if state in POLLING and self.next_due is None:
            self.next_due = now + self.interval
