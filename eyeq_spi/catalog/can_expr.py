"""The small expression language of ``specs/can/mapping.yaml`` (decision C4).

An expression (``-o.physicalState.latDistance``, ``table('obstacle_type', o.classification)``)
is parsed with :mod:`ast` and only whitelisted nodes are accepted: source names, attribute
access, literals, arithmetic, comparisons, boolean logic, ``x if c else y``, one-generator list
comprehensions and :data:`FUNCTIONS`, so the data stays data. A missing message or field or a
division by zero makes the whole expression :data:`MISSING` (the signal's invalid value is sent)."""

from __future__ import annotations

import ast
import math
from collections.abc import Callable
from typing import Any

from eyeq_spi.errors import SpecError


class _Missing:
    def __repr__(self) -> str:
        return "MISSING"


MISSING: Any = _Missing()


class _AbsentError(Exception):
    pass


def _first(items: list[Any]) -> Any:
    if not items:
        raise _AbsentError
    return items[0]


def _div(a: float, b: float) -> float:
    if b == 0:
        raise _AbsentError
    return a / b


def _take(items: list[Any], count: int) -> list[Any]:
    return list(items[: max(int(count), 0)])


FUNCTIONS: dict[str, Callable[..., Any]] = {
    "deg": math.degrees,    # radians -> degrees
    "rad": math.radians,    # degrees -> radians
    "atan": math.atan,
    "kmh": lambda v: v * 3.6,  # m/s -> km/h
    "count": len,           # length of a list
    "first": _first,        # first item of a list (MISSING when empty)
    "take": _take,          # the first n items of a list
    "div": _div,            # a / b, MISSING when b == 0
    "min": min, "max": max, "abs": abs, "int": int, "round": round,
    "any": any, "all": all, "bit": lambda cond, n: (1 << int(n)) if cond else 0,
}
_BINOPS: dict[type, Callable[[Any, Any], Any]] = {
    ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b, ast.Mod: lambda a, b: a % b, ast.FloorDiv: lambda a, b: a // b,
    ast.BitOr: lambda a, b: a | b, ast.BitAnd: lambda a, b: a & b,
}
_CMPOPS: dict[type, Callable[[Any, Any], bool]] = {
    ast.Eq: lambda a, b: a == b, ast.NotEq: lambda a, b: a != b, ast.Lt: lambda a, b: a < b,
    ast.LtE: lambda a, b: a <= b, ast.Gt: lambda a, b: a > b, ast.GtE: lambda a, b: a >= b,
    ast.In: lambda a, b: a in b, ast.NotIn: lambda a, b: a not in b,
}
Env = dict[str, Any]
Fn = Callable[[Env], Any]


def _build(node: ast.AST, names: set[str], tables: set[str]) -> Fn:
    """The evaluator of one node of a mapping expression (each node kind has its builder)."""
    builder = _BUILDERS.get(type(node))
    fn = builder(node, names, tables) if builder is not None else None
    if fn is None:
        raise SpecError(f"{type(node).__name__} is not part of the mapping language")
    return fn


def _constant(node: Any, names: set[str], tables: set[str]) -> Fn | None:
    value = node.value
    if not isinstance(value, (int, float, str)):
        return None
    return lambda env: value


def _name(node: Any, names: set[str], tables: set[str]) -> Fn:
    if node.id not in names:
        raise SpecError(f"unknown name {node.id!r} (known: {', '.join(sorted(names))})")
    key = node.id

    def name(env: Env) -> Any:
        value = env.get(key)
        if value is None or value is MISSING:
            raise _AbsentError
        return value
    return name


def _attribute(node: Any, names: set[str], tables: set[str]) -> Fn:
    if node.attr.startswith("_"):
        raise SpecError(f"attribute {node.attr!r} is not allowed")
    base, attr = _build(node.value, names, tables), node.attr

    def get(env: Env) -> Any:
        obj = base(env)
        if not isinstance(obj, dict) or attr not in obj:
            raise _AbsentError
        return obj[attr]
    return get


def _subscript(node: Any, names: set[str], tables: set[str]) -> Fn:
    base, index = _build(node.value, names, tables), _build(node.slice, names, tables)

    def sub(env: Env) -> Any:
        try:
            return base(env)[index(env)]
        except (IndexError, KeyError, TypeError):
            raise _AbsentError from None
    return sub


def _unary(node: Any, names: set[str], tables: set[str]) -> Fn | None:
    if not isinstance(node.op, (ast.USub, ast.Not, ast.UAdd)):
        return None
    operand, op = _build(node.operand, names, tables), node.op
    if isinstance(op, ast.USub):
        return lambda env: -operand(env)
    if isinstance(op, ast.Not):
        return lambda env: not operand(env)
    return operand


def _binary(node: Any, names: set[str], tables: set[str]) -> Fn | None:
    if type(node.op) not in _BINOPS:
        return None
    left, right, fn = (_build(node.left, names, tables), _build(node.right, names, tables),
                       _BINOPS[type(node.op)])

    def binop(env: Env) -> Any:
        try:
            return fn(left(env), right(env))
        except ZeroDivisionError:
            raise _AbsentError from None
    return binop


def _boolean(node: Any, names: set[str], tables: set[str]) -> Fn:
    parts = [_build(v, names, tables) for v in node.values]
    if isinstance(node.op, ast.And):
        return lambda env: all(p(env) for p in parts)
    return lambda env: any(p(env) for p in parts)


def _compare(node: Any, names: set[str], tables: set[str]) -> Fn | None:
    if not all(type(o) in _CMPOPS for o in node.ops):
        return None
    first = _build(node.left, names, tables)
    rest = [(_CMPOPS[type(o)], _build(c, names, tables))
            for o, c in zip(node.ops, node.comparators, strict=True)]

    def compare(env: Env) -> bool:
        left = first(env)
        for fn, operand in rest:
            right = operand(env)
            if not fn(left, right):
                return False
            left = right
        return True
    return compare


def _if(node: Any, names: set[str], tables: set[str]) -> Fn:
    test, body, orelse = (_build(node.test, names, tables), _build(node.body, names, tables),
                          _build(node.orelse, names, tables))
    return lambda env: body(env) if test(env) else orelse(env)


def _sequence(node: Any, names: set[str], tables: set[str]) -> Fn:
    items = [_build(e, names, tables) for e in node.elts]
    return lambda env: [i(env) for i in items]


def _comprehension(node: Any, names: set[str], tables: set[str]) -> Fn | None:
    if len(node.generators) != 1:
        return None
    gen = node.generators[0]
    if not isinstance(gen.target, ast.Name) or gen.is_async:
        raise SpecError("a comprehension binds one plain name")
    var = gen.target.id
    inner = names | {var}
    it = _build(gen.iter, names, tables)
    conds = [_build(c, inner, tables) for c in gen.ifs]
    elt = _build(node.elt, inner, tables)

    def comp(env: Env) -> list[Any]:
        out = []
        for item in it(env):
            local = {**env, var: item}
            if all(c(local) for c in conds):
                out.append(elt(local))
        return out
    return comp


def _call(node: Any, names: set[str], tables: set[str]) -> Fn | None:
    if not isinstance(node.func, ast.Name) or node.keywords:
        return None
    fname = node.func.id
    if fname == "table":
        if (len(node.args) != 2 or not isinstance(node.args[0], ast.Constant)
                or node.args[0].value not in tables):
            raise SpecError(f"table() takes a table name of {sorted(tables)} and a value")
        tname = str(node.args[0].value)
        arg = _build(node.args[1], names, tables)

        def lookup(env: Env) -> Any:
            table = env["__tables__"][tname]
            value = arg(env)
            return table[value] if value in table else table.get("default", MISSING)
        return lookup
    if fname not in FUNCTIONS:
        raise SpecError(f"unknown function {fname!r} (known: table, "
                        f"{', '.join(sorted(FUNCTIONS))})")
    fn, args = FUNCTIONS[fname], [_build(a, names, tables) for a in node.args]
    return lambda env: fn(*(a(env) for a in args))


_BUILDERS: dict[type, Callable[[Any, set[str], set[str]], Fn | None]] = {
    ast.Constant: _constant, ast.Name: _name, ast.Attribute: _attribute,
    ast.Subscript: _subscript, ast.UnaryOp: _unary, ast.BinOp: _binary, ast.BoolOp: _boolean,
    ast.Compare: _compare, ast.IfExp: _if, ast.Tuple: _sequence, ast.List: _sequence,
    ast.ListComp: _comprehension, ast.Call: _call,
}


def compile_expr(text: str, names: set[str], tables: set[str]) -> Callable[[Env], Any]:
    """Compile ``text``; the result maps an environment to a value or :data:`MISSING`."""
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        raise SpecError(f"{text!r}: {exc.msg}") from None
    fn = _build(tree.body, names, tables)

    def run(env: Env) -> Any:
        try:
            return fn(env)
        except (_AbsentError, TypeError, ValueError, OverflowError):
            return MISSING
    return run
