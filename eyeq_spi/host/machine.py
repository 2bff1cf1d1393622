"""The host's bring-up and mode state machine, as data (docs/STYLE.md §3).

Theory of operation (seed 004 §6 message flow, §7.1.3, §7.1.1.1.4)
---------------------------------------------------------------
POWER_UP waits for EYEQ_BOOT_STATUS_MSG and checks its test bits; a failure resets the EyeQ and
is retried, and the third failure in a row ends in BOOT_FAILED. WAIT_PENDING polls Get Extended
State until Pending Vision. INIT sends the init messages in order — 0x84 from NVM, 0x78/0x79 when
the configuration is camera-only AEB, then 0x92 — each answered by EventCalibrationTool. A 0x41
Fatal_Error 22 before vision leads to READ_EEPROM: the EEPROM's CRC decides between FAILED
("repair or replace") and a new NVM plus an EyeQ reset. WAIT_RUNNING sends HOST_VEH_STATE_MSG,
asks Get Versions once per ignition cycle and polls until Running Vision. RUNNING_VISION receives
the DASP stream. A new boot status or a 0x41 state that goes back is an EyeQ reset: the bring-up
runs again. FAILED and BOOT_FAILED are terminal for the ignition cycle: only the next one
(IGNITION) starts the bring-up afresh. A mode switch stops DASP, switches the application and,
for TAC/SPC, sends the mode's init message and waits for the results.

``TRANSITIONS`` maps (state, event) to the next state; a pair that is not in the table is ignored
and counted. ``ENTRY_ACTIONS`` names the host method run on entering a state (every state is either
there or in ``NO_ENTRY_ACTION``, checked at import); the host checks at import that each name is one
of its methods. A subclass changes an entry action by overriding the method the table names.
"""

from __future__ import annotations

import enum


class HostState(enum.Enum):
    POWER_UP = "POWER_UP"
    BOOT_FAILED = "BOOT_FAILED"
    WAIT_PENDING = "WAIT_PENDING"
    INIT = "INIT"
    READ_EEPROM = "READ_EEPROM"
    FAILED = "FAILED"
    WAIT_RUNNING = "WAIT_RUNNING"
    RUNNING_VISION = "RUNNING_VISION"
    FATAL = "FATAL"
    SWITCHING = "SWITCHING"
    WAIT_MODE_PENDING = "WAIT_MODE_PENDING"
    MODE_INIT = "MODE_INIT"
    WAIT_MODE_RUNNING = "WAIT_MODE_RUNNING"
    RUNNING_TAC = "RUNNING_TAC"
    RUNNING_SPC = "RUNNING_SPC"
    DV = "DV"


class HostEvent(enum.Enum):
    BOOT_OK = "BOOT_OK"
    BOOT_BAD = "BOOT_BAD"  # test bits set, or no boot status in time: reset and retry
    BOOT_STRIKE_OUT = "BOOT_STRIKE_OUT"  # the third failure in a row
    PENDING_VISION = "PENDING_VISION"
    INIT_DONE = "INIT_DONE"
    INIT_REJECTED = "INIT_REJECTED"
    FATAL_22 = "FATAL_22"
    EEPROM_OK = "EEPROM_OK"  # NVM rewritten; the EyeQ is reset
    EEPROM_BAD = "EEPROM_BAD"
    RUNNING_VISION = "RUNNING_VISION"
    FATAL = "FATAL"
    EYEQ_RESET = "EYEQ_RESET"
    SWITCH = "SWITCH"  # the API asked for another mode
    SWITCH_ACCEPTED = "SWITCH_ACCEPTED"
    SWITCH_REJECTED = "SWITCH_REJECTED"
    MODE_PENDING = "MODE_PENDING"  # pending TAC/SPC reached
    MODE_VISION_PENDING = "MODE_VISION_PENDING"  # back to Pending Vision
    MODE_DV = "MODE_DV"
    MODE_PARAMS_ACCEPTED = "MODE_PARAMS_ACCEPTED"
    RUNNING_TAC = "RUNNING_TAC"
    RUNNING_SPC = "RUNNING_SPC"
    # the next ignition cycle after the host gave up (live.drive: a new connection under
    # --reconnect); a fresh bring-up with the same NVM
    IGNITION = "IGNITION"


S, E = HostState, HostEvent

TRANSITIONS: dict[tuple[HostState, HostEvent], HostState] = {
    (S.POWER_UP, E.BOOT_OK): S.WAIT_PENDING,
    (S.POWER_UP, E.BOOT_BAD): S.POWER_UP,
    (S.POWER_UP, E.BOOT_STRIKE_OUT): S.BOOT_FAILED,
    (S.WAIT_PENDING, E.PENDING_VISION): S.INIT,
    (S.INIT, E.INIT_DONE): S.WAIT_RUNNING,
    (S.INIT, E.INIT_REJECTED): S.FAILED,
    (S.INIT, E.FATAL_22): S.READ_EEPROM,
    (S.WAIT_RUNNING, E.FATAL_22): S.READ_EEPROM,
    (S.WAIT_PENDING, E.FATAL_22): S.READ_EEPROM,
    (S.READ_EEPROM, E.EEPROM_OK): S.POWER_UP,
    (S.READ_EEPROM, E.EEPROM_BAD): S.FAILED,
    (S.WAIT_RUNNING, E.RUNNING_VISION): S.RUNNING_VISION,
    (S.WAIT_RUNNING, E.FATAL): S.FATAL,
    (S.RUNNING_VISION, E.FATAL): S.FATAL,
    (S.RUNNING_VISION, E.SWITCH): S.SWITCHING,
    (S.RUNNING_TAC, E.SWITCH): S.SWITCHING,
    (S.RUNNING_SPC, E.SWITCH): S.SWITCHING,
    (S.DV, E.SWITCH): S.SWITCHING,
    (S.SWITCHING, E.SWITCH_ACCEPTED): S.WAIT_MODE_PENDING,
    (S.SWITCHING, E.SWITCH_REJECTED): S.FAILED,
    (S.WAIT_MODE_PENDING, E.MODE_PENDING): S.MODE_INIT,
    (S.WAIT_MODE_PENDING, E.MODE_VISION_PENDING): S.INIT,
    (S.WAIT_MODE_PENDING, E.MODE_DV): S.DV,
    (S.MODE_INIT, E.MODE_PARAMS_ACCEPTED): S.WAIT_MODE_RUNNING,
    (S.MODE_INIT, E.INIT_REJECTED): S.FAILED,
    (S.WAIT_MODE_RUNNING, E.RUNNING_TAC): S.RUNNING_TAC,
    (S.WAIT_MODE_RUNNING, E.RUNNING_SPC): S.RUNNING_SPC,
}
# An EyeQ reset re-runs the bring-up from every state except the terminal ones: a host that
# gave up (§7.1.3 step 6: "the unit is failed") stays quiet until the next ignition cycle.
TERMINAL = frozenset({S.BOOT_FAILED, S.FAILED})
for _state in HostState:
    if _state not in TERMINAL:
        TRANSITIONS[(_state, E.EYEQ_RESET)] = S.POWER_UP
    else:
        TRANSITIONS[(_state, E.IGNITION)] = S.POWER_UP
    if _state not in TERMINAL and _state is not S.READ_EEPROM:
        TRANSITIONS.setdefault((_state, E.FATAL), S.FATAL)


# The host method run on entering each state (host/host.py). States that share a name share
# the action: the three waits poll Get Extended State.
ENTRY_ACTIONS: dict[HostState, str] = {
    S.POWER_UP: "entry_await_boot",  # §7.1.1.1.4: wait for EYEQ_BOOT_STATUS_MSG, fresh counters
    S.WAIT_PENDING: "entry_poll_state",
    S.INIT: "entry_send_init",  # 0x84, 0x78/0x79 (camera-only AEB), 0x92
    S.READ_EEPROM: "entry_read_eeprom",  # §7.1.3
    S.WAIT_RUNNING: "entry_start_vehicle_state",  # HOST_VEH_STATE_MSG, Get Versions, poll
    S.RUNNING_VISION: "entry_watch_streams",  # stale detection of the DASP streams
    S.FATAL: "entry_stop_watching",
    S.SWITCHING: "entry_request_switch",  # §6 flow step 16
    S.WAIT_MODE_PENDING: "entry_poll_state",
    S.MODE_INIT: "entry_send_mode_init",
    S.WAIT_MODE_RUNNING: "entry_poll_state",
}
NO_ENTRY_ACTION = frozenset({S.BOOT_FAILED, S.FAILED, S.RUNNING_TAC, S.RUNNING_SPC, S.DV})


def _check_entry_actions() -> None:
    both = NO_ENTRY_ACTION & ENTRY_ACTIONS.keys()
    neither = set(HostState) - NO_ENTRY_ACTION - ENTRY_ACTIONS.keys()
    if both or neither:
        raise RuntimeError(  # a programming error in this table, found at import
            f"ENTRY_ACTIONS: states in both tables {sorted(s.value for s in both)}, "
            f"in neither {sorted(s.value for s in neither)}")


_check_entry_actions()


_OLD_STYLE = frozenset(f"_on_{state.value.lower()}" for state in HostState)


def check_entry_handlers(cls: type, *, subclass: bool) -> None:
    """Every method ``ENTRY_ACTIONS`` names exists on ``cls`` (a renamed or removed action
    fails at import); a ``subclass`` defines no ``entry_*`` method the table does not name and
    no entry action of the old naming, ``_on_<state>`` (it would never run)."""
    named = set(ENTRY_ACTIONS.values())
    if not subclass:
        missing = [n for n in sorted(named) if not callable(getattr(cls, n, None))]
        if missing:
            raise RuntimeError(f"ENTRY_ACTIONS names {', '.join(missing)}, which "
                               f"{cls.__name__} lacks")
        return
    stray = [n for n in vars(cls) if (n.startswith("entry_") and n not in named)
             or n in _OLD_STYLE]
    if stray:
        raise TypeError(
            f"{cls.__name__} defines {', '.join(stray)}, which no state runs: entry actions "
            f"are the methods named in host/machine.py ENTRY_ACTIONS ({', '.join(sorted(named))})")


def next_state(state: HostState, event: HostEvent) -> HostState | None:
    return TRANSITIONS.get((state, event))


def diagram() -> str:
    """The transition table as a Mermaid state diagram (README, docs)."""
    lines = ["stateDiagram-v2", "    [*] --> POWER_UP"]
    for (src, ev), dst in TRANSITIONS.items():
        if ev in (E.EYEQ_RESET, E.FATAL) and src not in (S.RUNNING_VISION, S.WAIT_RUNNING):
            continue  # drawn once below
        lines.append(f"    {src.value} --> {dst.value}: {ev.value}")
    lines.append("    note right of POWER_UP: EYEQ_RESET from any non-terminal state")
    return "\n".join(lines)
