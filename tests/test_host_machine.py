"""The host's entry actions are a table beside TRANSITIONS (host/machine.py), bound to methods
of the host at import; a subclass replaces one by overriding the method the table names."""

from __future__ import annotations

import pytest

from eyeq_spi.host.host import HostEmulator
from eyeq_spi.host.machine import ENTRY_ACTIONS, NO_ENTRY_ACTION, HostState

S = HostState

# the states that run an action on entry (seed 004 §6 flow, §7.1.3)
WITH_ACTION = {S.POWER_UP, S.WAIT_PENDING, S.INIT, S.READ_EEPROM, S.WAIT_RUNNING,
               S.RUNNING_VISION, S.FATAL, S.SWITCHING, S.WAIT_MODE_PENDING, S.MODE_INIT,
               S.WAIT_MODE_RUNNING}


def test_every_state_with_an_entry_action_keeps_it() -> None:
    assert set(ENTRY_ACTIONS) == WITH_ACTION
    assert set(HostState) - WITH_ACTION == NO_ENTRY_ACTION
    for state, name in ENTRY_ACTIONS.items():
        assert callable(getattr(HostEmulator, name, None)), (state, name)


def test_the_three_waits_poll_the_state() -> None:
    assert {ENTRY_ACTIONS[s] for s in (S.WAIT_PENDING, S.WAIT_MODE_PENDING,
                                       S.WAIT_MODE_RUNNING)} == {"entry_poll_state"}


@pytest.mark.parametrize("name", ["_on_read_eeprom", "_on_wait_running", "entry_read_eprom"])
def test_an_override_no_state_runs_fails_at_class_creation(name: str) -> None:
    with pytest.raises(TypeError, match="ENTRY_ACTIONS"):
        type("Broken", (HostEmulator,), {name: lambda self, now: None})


def test_an_overridden_entry_action_runs_on_entry() -> None:
    seen: list[tuple[str, float]] = []

    class Recording(HostEmulator):
        def entry_await_boot(self, now: float) -> None:
            seen.append(("POWER_UP", now))
            super().entry_await_boot(now)

    host = Recording()
    host.start(1.5)
    assert seen == [("POWER_UP", 1.5)] and host.state is S.POWER_UP
    assert host.get_timer() == 1.5 + host.config.boot_timeout  # the default action ran too
