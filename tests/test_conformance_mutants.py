"""The proof that the suite can fail (issue 12): each deliberately broken variant of our
simulated EyeQ or host runs the whole suite and fails exactly the cases its bug violates. Every
other case keeps the verdict the correct implementation gets (pass; LINK-GAP skip in virtual
time), except the cases a mutant declares masked (its bug removes what they need): those must
be skip or inconclusive, never pass or fail. Virtual time.

The whole matrix runs in CI: the variants are independent, so they run in a pool of two
processes (about 2 s of CPU each)."""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor

import pytest

from eyeq_spi.conformance.cases import cases_for
from eyeq_spi.conformance.mutants import MUTANTS
from eyeq_spi.conformance.suite import Options, run

REALTIME_ONLY = {"LINK-GAP"}  # skip in virtual time, for the correct implementation too
GROUPS = {"link", "transport", "mesp", "dasp", "flows", "host"}

Verdicts = dict[str, tuple[str, str]]


def _run_one(name: str) -> Verdicts:
    m = MUTANTS[name]
    return {r.case.id: (r.outcome.verdict, r.outcome.evidence)
            for r in run(Options(dut=m.dut, builtin=True, mutant=name))}


@pytest.fixture(scope="module")
def matrix() -> dict[str, Verdicts]:
    names = sorted(MUTANTS)
    ctx = multiprocessing.get_context("fork") if os.name == "posix" else None
    with ProcessPoolExecutor(max_workers=2, mp_context=ctx) as pool:
        futures = {n: pool.submit(_run_one, n) for n in names}
        return {n: f.result(timeout=300) for n, f in futures.items()}


def test_enough_mutants_and_every_group_has_one() -> None:
    assert len(MUTANTS) >= 12
    by_id = {c.id: c for dut in ("eyeq", "host") for c in cases_for(dut)}
    covered = {by_id[c].group for m in MUTANTS.values() for c in m.expected}
    assert covered == GROUPS
    assert any("LINK-TXTIMEOUT" in m.expected for m in MUTANTS.values())
    for m in MUTANTS.values():
        assert m.expected and not m.expected & m.masks
        assert (m.expected | m.masks) <= {c.id for c in cases_for(m.dut)}, m.name


@pytest.mark.parametrize("name", sorted(MUTANTS))
def test_mutant_fails_exactly_its_cases(name: str, matrix: dict[str, Verdicts]) -> None:
    m, verdicts = MUTANTS[name], matrix[name]
    failed = {k for k, (v, _) in verdicts.items() if v == "fail"}
    evidence = {k: verdicts[k][1] for k in failed ^ set(m.expected)}
    assert failed == set(m.expected), evidence
    for k in failed:
        assert verdicts[k][1]  # frame indices, times, expected and seen
    changed = {}
    for k, (v, ev) in verdicts.items():
        if k in m.expected:
            continue
        want: tuple[str, ...] = ("skip",) if k in REALTIME_ONLY else ("pass",)
        if k in m.masks:
            want = ("skip", "inconclusive")
        if v not in want:
            changed[k] = (v, ev)
    assert not changed, changed
