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

``TRANSITIONS`` maps (state, event) to the next state (a pair not in it is ignored and counted);
``ENTRY_ACTIONS`` names the host method run on entering a state, checked at import."""

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


TRANSITIONS: dict[tuple[HostState, HostEvent], HostState] = {
    (HostState.POWER_UP, HostEvent.BOOT_OK): HostState.WAIT_PENDING,
    (HostState.POWER_UP, HostEvent.BOOT_BAD): HostState.POWER_UP,
    (HostState.POWER_UP, HostEvent.BOOT_STRIKE_OUT): HostState.BOOT_FAILED,
    (HostState.WAIT_PENDING, HostEvent.PENDING_VISION): HostState.INIT,
    (HostState.INIT, HostEvent.INIT_DONE): HostState.WAIT_RUNNING,
    (HostState.INIT, HostEvent.INIT_REJECTED): HostState.FAILED,
    (HostState.INIT, HostEvent.FATAL_22): HostState.READ_EEPROM,
    (HostState.WAIT_RUNNING, HostEvent.FATAL_22): HostState.READ_EEPROM,
    (HostState.WAIT_PENDING, HostEvent.FATAL_22): HostState.READ_EEPROM,
    (HostState.READ_EEPROM, HostEvent.EEPROM_OK): HostState.POWER_UP,
    (HostState.READ_EEPROM, HostEvent.EEPROM_BAD): HostState.FAILED,
    (HostState.WAIT_RUNNING, HostEvent.RUNNING_VISION): HostState.RUNNING_VISION,
    (HostState.WAIT_RUNNING, HostEvent.FATAL): HostState.FATAL,
    (HostState.RUNNING_VISION, HostEvent.FATAL): HostState.FATAL,
    (HostState.RUNNING_VISION, HostEvent.SWITCH): HostState.SWITCHING,
    (HostState.RUNNING_TAC, HostEvent.SWITCH): HostState.SWITCHING,
    (HostState.RUNNING_SPC, HostEvent.SWITCH): HostState.SWITCHING,
    (HostState.DV, HostEvent.SWITCH): HostState.SWITCHING,
    (HostState.SWITCHING, HostEvent.SWITCH_ACCEPTED): HostState.WAIT_MODE_PENDING,
    (HostState.SWITCHING, HostEvent.SWITCH_REJECTED): HostState.FAILED,
    (HostState.WAIT_MODE_PENDING, HostEvent.MODE_PENDING): HostState.MODE_INIT,
    (HostState.WAIT_MODE_PENDING, HostEvent.MODE_VISION_PENDING): HostState.INIT,
    (HostState.WAIT_MODE_PENDING, HostEvent.MODE_DV): HostState.DV,
    (HostState.MODE_INIT, HostEvent.MODE_PARAMS_ACCEPTED): HostState.WAIT_MODE_RUNNING,
    (HostState.MODE_INIT, HostEvent.INIT_REJECTED): HostState.FAILED,
    (HostState.WAIT_MODE_RUNNING, HostEvent.RUNNING_TAC): HostState.RUNNING_TAC,
    (HostState.WAIT_MODE_RUNNING, HostEvent.RUNNING_SPC): HostState.RUNNING_SPC,
}
# An EyeQ reset re-runs the bring-up from every state except the terminal ones: a host that
# gave up (§7.1.3 step 6: "the unit is failed") stays quiet until the next ignition cycle.
TERMINAL = frozenset({HostState.BOOT_FAILED, HostState.FAILED})
for _state in HostState:
    if _state not in TERMINAL:
        TRANSITIONS[(_state, HostEvent.EYEQ_RESET)] = HostState.POWER_UP
    else:
        TRANSITIONS[(_state, HostEvent.IGNITION)] = HostState.POWER_UP
    if _state not in TERMINAL and _state is not HostState.READ_EEPROM:
        TRANSITIONS.setdefault((_state, HostEvent.FATAL), HostState.FATAL)


# The host method run on entering each state (host/host.py). States that share a name share
# the action: the three waits poll Get Extended State.
ENTRY_ACTIONS: dict[HostState, str] = {
    # §7.1.1.1.4: wait for EYEQ_BOOT_STATUS_MSG, fresh counters
    HostState.POWER_UP: "entry_await_boot",
    HostState.WAIT_PENDING: "entry_poll_state",
    HostState.INIT: "entry_send_init",  # 0x84, 0x78/0x79 (camera-only AEB), 0x92
    HostState.READ_EEPROM: "entry_read_eeprom",  # §7.1.3
    HostState.WAIT_RUNNING: "entry_start_vehicle_state",  # HOST_VEH_STATE_MSG, Get Versions, poll
    HostState.RUNNING_VISION: "entry_watch_streams",  # stale detection of the DASP streams
    HostState.FATAL: "entry_stop_watching",
    HostState.SWITCHING: "entry_request_switch",  # §6 flow step 16
    HostState.WAIT_MODE_PENDING: "entry_poll_state",
    HostState.MODE_INIT: "entry_send_mode_init",
    HostState.WAIT_MODE_RUNNING: "entry_poll_state",
}
NO_ENTRY_ACTION = frozenset({HostState.BOOT_FAILED, HostState.FAILED, HostState.RUNNING_TAC,
                             HostState.RUNNING_SPC, HostState.DV})


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
    """Every method ``ENTRY_ACTIONS`` names exists on ``cls``; a ``subclass`` defines no
    ``entry_*`` method the table does not name, nor an ``_on_<state>`` one (it would never run)."""
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
        if ev in (HostEvent.EYEQ_RESET, HostEvent.FATAL) and src not in (
                HostState.RUNNING_VISION, HostState.WAIT_RUNNING):
            continue  # drawn once below
        lines.append(f"    {src.value} --> {dst.value}: {ev.value}")
    lines.append("    note right of POWER_UP: EYEQ_RESET from any non-terminal state")
    return "\n".join(lines)
