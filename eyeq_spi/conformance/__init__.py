"""Protocol conformance suite: plays the host against an EyeQ under test, or the EyeQ
against a host under test, judges one case per requirement from the recorded traffic, and
reports verdicts with evidence. ``--builtin`` runs it against our own implementations in
virtual time; ``mutants`` holds the broken variants that prove each case can fail.

From the bottom up: ``model`` (what every part shares), ``trace``, the two wings ``play`` (the
side we run) and ``judges`` (which read only traces), then ``cases``, ``load`` and ``mutants``,
``suite`` and ``report``; the layers contract in pyproject.toml keeps it so."""

from eyeq_spi.conformance.cases import all_cases, cases_for
from eyeq_spi.conformance.model import Case
from eyeq_spi.conformance.suite import Options, Result, run, select_cases

__all__ = ["Case", "Options", "Result", "all_cases", "cases_for", "run", "select_cases"]
