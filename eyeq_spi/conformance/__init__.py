"""Protocol conformance suite (docs/conformance.md): plays one side against an implementation
under test, judges one case per requirement from the recorded traffic, and reports verdicts
with evidence. Layers, bottom up: ``model``, ``trace``, ``play`` | ``judges``, ``cases`` |
``load`` | ``mutants``, ``suite``, ``report`` (the contract in pyproject.toml)."""

from eyeq_spi.conformance.cases import all_cases, cases_for
from eyeq_spi.conformance.model import Case
from eyeq_spi.conformance.suite import Options, Result, run, select_cases

__all__ = ["Case", "Options", "Result", "all_cases", "cases_for", "run", "select_cases"]
