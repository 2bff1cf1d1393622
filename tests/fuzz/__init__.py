"""Fuzz targets. Each target takes one input (bytes) and either returns, or
raises :class:`~tests.fuzz.core.Finding` (an oracle was violated) or :class:`~tests.fuzz.core.Hang`
(a step ran over its time limit); any other exception is a crash. The targets run under atheris
(``tools/fuzz.py --budget S``, coverage-guided) and under a seeded coverage-free mutator
(``tests/test_fuzz_slice.py``, every CI run)."""
