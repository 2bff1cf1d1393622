"""Protocol conformance suite (docs/conformance.md): plays one side against an implementation
under test, judges one case per requirement from the recorded traffic, and reports verdicts
with evidence. Layers, bottom up: ``model``, ``trace``, ``play`` | ``judges``, ``cases`` |
``load`` | ``mutants``, ``suite``, ``report`` (the contract in pyproject.toml)."""
