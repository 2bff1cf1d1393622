"""The error tree is indexed in ``eyeq_spi/errors.py``: every public error class of the package is
defined there, and the module that raises one still exports it under its old name."""

from __future__ import annotations

import ast
import importlib
import inspect
from pathlib import Path

import pytest

import eyeq_spi
from eyeq_spi import errors
from eyeq_spi.errors import EyeqError, MespError
from eyeq_spi.mesp.replies import MespFailure, MespReply, unwrap

PACKAGE = Path(eyeq_spi.__file__).parent
TREE = {name for name, obj in vars(errors).items()
        if inspect.isclass(obj) and issubclass(obj, BaseException)}


def _class_defs() -> list[tuple[str, str, list[str]]]:
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).as_posix()
        for node in ast.walk(ast.parse(path.read_text(), rel)):
            if isinstance(node, ast.ClassDef):
                bases = [b.id if isinstance(b, ast.Name) else
                         b.attr if isinstance(b, ast.Attribute) else "" for b in node.bases]
                found.append((rel, node.name, bases))
    return found


def test_no_public_error_class_is_defined_outside_errors_py() -> None:
    stray = [f"{rel}: {name}({', '.join(bases)})" for rel, name, bases in _class_defs()
             if rel != "eyeq_spi/errors.py" and not name.startswith("_")
             and (set(bases) & TREE or name.endswith("Error")
                  or any(b in ("Exception", "ValueError") for b in bases))]
    assert stray == []


# where each class was defined before it moved to errors.py: the old import keeps working
OLD_HOMES = {
    "eyeq_spi.catalog.can_expr": ["ExprError"],
    "eyeq_spi.phy.address": ["AddressError"],
    "eyeq_spi.can.compare": ["CanCompareError"],
    "eyeq_spi.can.dbc": ["CanExtraMissingError"],
    "eyeq_spi.can.sinks": ["CanOutputError"],
    "eyeq_spi.can.logs": ["CanLogError", "CanBusError", "CanLogTruncatedError"],
    "eyeq_spi.mesp.replies": ["MespError"],
    "eyeq_spi.mesp": ["MespError"],
    "eyeq_spi.monitor.view": ["MonitorError"],
    "eyeq_spi.capture.pcapng_io": ["CaptureError", "TruncatedCaptureError"],
    "eyeq_spi.host.nvm": ["NvmError"],
    "eyeq_spi.host.scenario": ["ScenarioError"],
    "eyeq_spi.logic.options": ["LogicInputError"],
    "eyeq_spi.plot": ["PlotError"],
    "eyeq_spi.dissect.output": ["OutputError"],
    "eyeq_spi.io.plain": ["InputError"],
    "eyeq_spi.dissect.engine_fast_frames": ["BatchUnsupportedError"],
    "eyeq_spi.dissect.fleet": ["FleetError"],
    "eyeq_spi.interop.replay": ["ReplayError"],
    "eyeq_spi.interop.mdf": ["ExportError"],
    "eyeq_spi.interop.sigrok_install": ["InstallError"],
}


@pytest.mark.parametrize("module", sorted(OLD_HOMES))
def test_the_old_import_paths_still_work(module: str) -> None:
    mod = importlib.import_module(module)
    for name in OLD_HOMES[module]:
        assert getattr(mod, name) is getattr(errors, name)


def test_every_error_is_in_the_tree_with_a_docstring() -> None:
    for name in TREE:
        cls = getattr(errors, name)
        assert issubclass(cls, EyeqError) and cls.__doc__, name


def test_a_mesp_failure_is_a_plain_value_raised_only_on_request() -> None:
    failure = MespFailure("FFSReadFile", 5, "FILE_NOT_FOUND", 1)
    assert not isinstance(failure, BaseException)
    assert str(failure) == "FFSReadFile: ret 5 (FILE_NOT_FOUND) after 1 attempt(s)"
    with pytest.raises(MespError) as info:
        unwrap(failure)
    assert (info.value.function, info.value.ret, info.value.ret_name) == (
        "FFSReadFile", 5, "FILE_NOT_FOUND")
    reply = MespReply("GetEyeQVersions", 1, None, 1, 0.01)
    assert unwrap(reply) is reply
    timeout = MespFailure("GetEyeQVersions", None, "no reply (timeout)", 3)
    assert str(timeout) == "GetEyeQVersions: no reply (timeout) after 3 attempt(s)"
