"""No module reads another's private members. An attribute ``X._name`` (not a dunder) is read
through ``self``, ``cls`` or ``super()``, or names a member its own module defines (a method of
a class reading another instance of it); a name with a leading underscore belongs to the
module that defines it, and what another module needs is made public there.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "eyeq_spi"
OWNERS = {"self", "cls"}

ALLOWED: dict[str, str] = {}
"""Files still to be cleared, each with why (none)."""

ARGPARSE = frozenset({"_actions", "_add_container_actions", "_choices_actions", "_defaults",
                      "_parser_class", "_SubParsersAction"})
"""argparse's own members that the CLI reads (its help text walks the sub-commands, and shared
option groups are placed where ``--help`` lists them): argparse has no public API for either,
and these have been stable for a decade. Our own modules' private members are never read."""


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _owner_ok(node: ast.expr) -> bool:
    if isinstance(node, ast.Name):
        return node.id in OWNERS
    return (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id == "super")


def _defined(tree: ast.Module) -> set[str]:
    """The private names a module defines: functions, classes, assigned names and attributes
    (``self._x = ...``), class-body fields (``_x: int``) and ``__slots__`` entries."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            names.add(node.value)  # __slots__ = ("_x", ...), getattr(obj, "_x") spelled out
    return {n for n in names if _private(n)}


def violations() -> list[tuple[str, int, str]]:
    found: list[tuple[str, int, str]] = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"), rel)
        own = _defined(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level == 0:  # from x import _y
                found += [(rel, node.lineno, a.name) for a in node.names
                          if _private(a.name) and rel not in ALLOWED]
            if (isinstance(node, ast.Attribute) and _private(node.attr)
                    and not _owner_ok(node.value) and node.attr not in own
                    and node.attr not in ARGPARSE
                    and rel not in ALLOWED):
                found.append((rel, node.lineno, node.attr))
    return found


def test_no_private_access_across_modules() -> None:
    assert violations() == []


def test_the_rule_catches_a_private_read(tmp_path: Path) -> None:
    tree = ast.parse("dis._dirs[1]\nself._ok\nsuper()._ok()\nx.__class__\n")
    hits = [n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)
            and _private(n.attr) and not _owner_ok(n.value)]
    assert hits == ["_dirs"]
