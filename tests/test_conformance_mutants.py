"""The proof that the suite can fail (issue 12): each deliberately broken variant of our
simulated EyeQ or host fails exactly the cases its bug violates; every other case keeps the
verdict the correct implementation gets (pass), or becomes inconclusive/skip when the bug
removes what it needs. Virtual time.

Each variant runs the whole suite (2-3 s of CPU). By default one variant per group runs, to stay
inside the CI time budget; ``EYEQ_CONFORMANCE_MUTANTS=all`` runs the whole matrix."""

from __future__ import annotations

import os

import pytest

from eyeq_spi.conformance.mutants import MUTANTS
from eyeq_spi.conformance.suite import Options, run

assert len(MUTANTS) >= 12
DEFAULT = ("eyeq-wrong-rsp", "eyeq-tag-not-echoed", "eyeq-dasp-counter-stuck",
           "eyeq-running-without-veh-state", "host-no-eeprom-reread")
CHOSEN = sorted(MUTANTS) if os.environ.get("EYEQ_CONFORMANCE_MUTANTS") == "all" else DEFAULT


@pytest.mark.parametrize("name", CHOSEN)
def test_mutant_fails_exactly_its_cases(name: str) -> None:
    m = MUTANTS[name]
    results = run(Options(dut=m.dut, builtin=True, mutant=name))
    failed = {r.case.id for r in results if r.outcome.verdict == "fail"}
    evidence = {r.case.id: r.outcome.evidence for r in results if r.case.id in failed}
    assert failed == set(m.expected), evidence
    for r in results:
        if r.case.id in failed:
            assert r.outcome.evidence  # frame indices, times, expected and seen
