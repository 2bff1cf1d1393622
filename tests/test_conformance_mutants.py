"""The proof that the suite can fail: each deliberately broken variant of our
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
from eyeq_spi.conformance.mutants import ADVISED, CORRECT, MUTANTS
from eyeq_spi.conformance.suite import Options, run

GROUPS = {"link", "transport", "mesp", "dasp", "flows", "host"}

Verdicts = dict[str, tuple[str, str]]


def _run_one(name: str) -> Verdicts:
    m = MUTANTS.get(name) or ADVISED.get(name) or CORRECT[name]
    return {r.case.id: (r.outcome.verdict, r.outcome.evidence)
            for r in run(Options(dut=m.dut, builtin=True, mutant=name))}


def _run_clean(dut: str) -> Verdicts:
    return {r.case.id: (r.outcome.verdict, r.outcome.evidence)
            for r in run(Options(dut=dut, builtin=True))}


@pytest.fixture(scope="module")
def matrix() -> dict[str, Verdicts]:
    """Every mutant, every advised variant and the two correct implementations ("clean-eyeq",
    "clean-host"): the baseline each mutant is compared with."""
    names = sorted(MUTANTS) + sorted(ADVISED) + sorted(CORRECT)
    ctx = multiprocessing.get_context("fork") if os.name == "posix" else None
    with ProcessPoolExecutor(max_workers=2, mp_context=ctx) as pool:
        futures = {n: pool.submit(_run_one, n) for n in names}
        futures |= {f"clean-{d}": pool.submit(_run_clean, d) for d in ("eyeq", "host")}
        return {n: f.result(timeout=300) for n, f in futures.items()}


def test_enough_mutants_and_every_group_has_one() -> None:
    assert len(MUTANTS) >= 12
    # each rule this suite added has a mutant the earlier suite let through
    assert {"host-late-acks", "host-ack-pad", "eyeq-ack-pad", "host-no-retry",
            "host-no-renumber"} <= set(MUTANTS)
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
    clean = matrix[f"clean-{m.dut}"]
    changed = {}
    for k, (v, ev) in verdicts.items():
        if k in m.expected:
            continue
        want: tuple[str, ...] = (clean[k][0],)
        if k in m.masks:
            want = ("skip", "inconclusive")
        if v not in want:
            changed[k] = (v, ev)
    assert not changed, changed


@pytest.mark.parametrize("name", sorted(ADVISED))
def test_advised_variants_pass_with_advice(name: str, matrix: dict[str, Verdicts]) -> None:
    """A host that departs only from our recommendation (asks Get Versions again, resets a
    failing EyeQ more than 3 times) passes: the case says so as advice, citing the seed."""
    m, verdicts = ADVISED[name], matrix[name]
    assert not {k for k, (v, _) in verdicts.items() if v == "fail"}
    for k in m.expected:
        v, ev = verdicts[k]
        assert v == "pass" and "advice:" in ev, (k, v, ev)


@pytest.mark.parametrize("name", sorted(CORRECT))
def test_correct_variants_get_our_verdicts(name: str, matrix: dict[str, Verdicts]) -> None:
    """A host that differs from ours and breaks no rule gets, case by case, the verdict ours
    gets: a host that learns of our reset late (its boot status lost, the reset seen from 0x41
    Main_State) and numbers from 0 again with a stale RSP is accepted by our EyeQ (L10a), and
    every judge follows what our EyeQ accepted (its requests after the restart, tags 17 on,
    0x84 and 0x92 included)."""
    m, verdicts = CORRECT[name], matrix[name]
    clean = matrix[f"clean-{m.dut}"]
    assert {k: v for k, (v, _) in verdicts.items()} == {k: v for k, (v, _) in clean.items()}, \
        {k: verdicts[k] for k in verdicts if verdicts[k][0] != clean[k][0]}


def test_clean_implementations_pass_or_say_why_not(matrix: dict[str, Verdicts]) -> None:
    """The correct implementations fail nothing; a case they do not exercise is a skip with
    its reason (our host sends only single frames: LINK-WINDOW, LINK-TXTIMEOUT), never a
    pass."""
    for dut in ("eyeq", "host"):
        verdicts = matrix[f"clean-{dut}"]
        assert {v for v, _ in verdicts.values()} <= {"pass", "skip"}, verdicts
        skipped = {k for k, (v, _) in verdicts.items() if v == "skip"}
        assert "LINK-GAP" in skipped
    host = matrix["clean-host"]
    assert host["LINK-TXTIMEOUT"] == ("skip", "the DUT sent no multi-frame transfer: every "
                                      "message fitted one frame")
    assert host["LINK-WINDOW"][0] == "skip" and "not exercised" in host["LINK-WINDOW"][1]
    assert "advice" not in host["HOST-VERSIONS"][1]
