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
