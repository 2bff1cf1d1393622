"""No module of the package is over 600 lines and no function over 80 (docs/STYLE.md): a longer
module does more than one job and is split by job (the simulated EyeQ's MESP answers beside
its boot and DASP), never a class cut in two to pass; a longer function likewise."""

from __future__ import annotations

import ast
from pathlib import Path

import eyeq_spi

LIMIT = 600
PACKAGE = Path(eyeq_spi.__file__).parent


def test_no_module_is_over_600_lines() -> None:
    long = {p.relative_to(PACKAGE.parent).as_posix(): n for p in sorted(PACKAGE.rglob("*.py"))
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > LIMIT}
    assert long == {}, f"split these modules along a seam (limit {LIMIT} lines): {long}"


FUNCTION_LIMIT = 80


def test_no_function_is_over_80_lines() -> None:
    """A function does one job and fits one screen (docs/STYLE.md): a longer one is split by
    job, each piece named from the seed or the domain."""
    long = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                if lines > FUNCTION_LIMIT:
                    long[f"{rel}:{node.lineno} {node.name}"] = lines
    assert long == {}, f"split these functions by job (limit {FUNCTION_LIMIT} lines): {long}"


SPEED_ONLY_LIMIT = 2_000


def test_speed_only_code_stays_in_its_leaves_and_within_its_budget() -> None:
    """Fast code lives only in the leaves ``eyeq_spi/twins.py`` lists (``*_fast*.py``), and all
    of it together is at most 2,000 lines: a leaf stays only while a floor of
    docs/performance.md needs it, so speed never grows into a second core."""
    from eyeq_spi.twins import FAMILIES

    leaves = {p.relative_to(PACKAGE.parent).as_posix(): len(p.read_text("utf-8").splitlines())
              for p in sorted(PACKAGE.rglob("*_fast*.py"))}
    listed = {fast.replace(".", "/") + ".py" for _, fast in FAMILIES.values() if "/" not in fast
              and fast.startswith("eyeq_spi.")}
    assert listed <= set(leaves), f"a family's fast twin is missing: {listed - set(leaves)}"
    packages = {name.rsplit("/", 1)[0] for name in listed}  # a family's leaves share its package
    strays = [name for name in leaves if name.rsplit("/", 1)[0] not in packages]
    assert strays == [], f"fast modules outside the families of eyeq_spi/twins.py: {strays}"
    total = sum(leaves.values())
    assert total <= SPEED_ONLY_LIMIT, f"speed-only code {total} lines (budget "\
        f"{SPEED_ONLY_LIMIT}): {leaves}"
