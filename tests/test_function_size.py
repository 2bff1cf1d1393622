"""No function of the package is over 80 lines (docs/STYLE.md): a longer one does more than
one job. ``LONGER`` lists the functions still over the limit; it only shrinks (an entry whose
function is gone or now short fails too, so the list stays true)."""

from __future__ import annotations

import ast
from pathlib import Path

import eyeq_spi

LIMIT = 80
PACKAGE = Path(eyeq_spi.__file__).parent

LONGER = {
    "eyeq_spi/catalog/schema.py:validate_tree",
    "eyeq_spi/codec/layout.py:_compile",
    "eyeq_spi/conformance/cases.py:_static",
    "eyeq_spi/logic/saleae_fast.py:saleae2_chunk",
    "eyeq_spi/logic/vcd_fast.py:_channel",
}


def _long_functions() -> set[str]:
    found = set()
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and \
                    (node.end_lineno or node.lineno) - node.lineno + 1 > LIMIT:
                found.add(f"{path.relative_to(PACKAGE.parent).as_posix()}:{node.name}")
    return found


def test_no_function_is_over_80_lines() -> None:
    found = _long_functions()
    assert found - LONGER == set(), f"split these along their jobs (limit {LIMIT} lines)"
    assert LONGER - found == set(), "no longer over the limit: take them off LONGER"
