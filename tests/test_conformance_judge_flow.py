"""HOST-EEPROM-BAD (§7.1.3 step 6: after a bad EEPROM CRC "the unit is failed"): "the host
stopped" needs the host watched, quiet and connected, for QUIET_FOR after the EEPROM reply; a
shorter watch (a host that closed its port at once) proves nothing and is inconclusive. Our
tester EyeQ against our host in virtual time, the eeprom_bad ignition cycle only."""

from __future__ import annotations

from eyeq_spi.conformance.judges.app import DEADLINE
from eyeq_spi.conformance.judges.flow import QUIET_FOR
from eyeq_spi.conformance.judges.verdict import Outcome
from eyeq_spi.conformance.suite import Options, run


def _eeprom_bad(watch: float, mutant: str | None = None) -> Outcome:
    """HOST-EEPROM-BAD after watching the host for ``watch`` s past the EEPROM reply (+ the
    script's 0.05 s)."""
    opts = Options(dut="host", builtin=True, select="HOST-EEPROM-BAD", mutant=mutant)
    opts.eyeq_plan.eeprom_watch = watch
    [res] = run(opts)
    return res.outcome


def test_the_quiet_window_is_the_mesp_deadline_and_half_a_second() -> None:
    assert DEADLINE == 0.5  # M6, specs/mesp.yaml
    assert QUIET_FOR == DEADLINE + 0.5


def test_a_host_watched_less_than_the_window_is_inconclusive() -> None:
    out = _eeprom_bad(0.3)
    assert out.verdict == "inconclusive", out
    assert "0.35 s later" in out.evidence and "1.0 s" in out.evidence, out


def test_a_host_quiet_for_the_window_passes() -> None:
    out = _eeprom_bad(QUIET_FOR)
    assert out.verdict == "pass", out
    assert "for 1.05 s, at least 1.0 s" in out.evidence, out


def test_a_host_that_carries_on_fails() -> None:
    out = _eeprom_bad(QUIET_FOR, mutant="host-ignores-bad-eeprom")
    assert out.verdict == "fail", out
    assert "reset us" in out.evidence, out


def test_a_host_that_carries_on_fails_even_in_a_short_watch() -> None:
    """What the host did is judged before how long it was watched."""
    assert _eeprom_bad(0.3, mutant="host-ignores-bad-eeprom").verdict == "fail"
