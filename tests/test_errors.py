"""The error tree of ``eyeq_spi/errors.py``: every public error class of the package is defined
there, with a docstring, at most twelve of them; a failed MESP request is a value until asked
for an exception; and the CLI turns a spec mistake into one line naming the file and entry."""

from __future__ import annotations

import ast
import inspect
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import eyeq_spi
from eyeq_spi import errors
from eyeq_spi.errors import EyeqError, MissingExtra, RemoteProtocolError
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


def test_the_tree_is_small_and_every_class_says_when_it_is_raised() -> None:
    assert len(TREE) <= 12, sorted(TREE)
    for name in TREE:
        cls = getattr(errors, name)
        assert issubclass(cls, EyeqError) and cls.__doc__, name
        assert name in (errors.__doc__ or ""), f"{name} is not drawn in the module docstring"


def test_missing_extra_names_the_pip_extra() -> None:
    exc = MissingExtra("plot", "plots need matplotlib")
    assert (exc.extra, exc.what) == ("plot", "plots need matplotlib")
    assert str(exc) == "plots need matplotlib: pip install 'eyeq-spi[plot]'"


def test_a_mesp_failure_is_a_plain_value_raised_only_on_request() -> None:
    failure = MespFailure("FFSReadFile", 5, "FILE_NOT_FOUND", 1)
    assert not isinstance(failure, BaseException)
    assert str(failure) == "FFSReadFile: ret 5 (FILE_NOT_FOUND) after 1 attempt(s)"
    with pytest.raises(RemoteProtocolError, match=r"^FFSReadFile: ret 5 \(FILE_NOT_FOUND\)"):
        unwrap(failure)
    reply = MespReply("GetEyeQVersions", 1, None, 1, 0.01)
    assert unwrap(reply) is reply
    timeout = MespFailure("GetEyeQVersions", None, "no reply (timeout)", 3)
    assert str(timeout) == "GetEyeQVersions: no reply (timeout) after 3 attempt(s)"


def test_a_broken_spec_entry_is_one_line_naming_the_file_and_entry(tmp_path: Path) -> None:
    """A spec entry the Wireshark generator cannot use (a link type outside LINKTYPE_USER0..15)
    reaches a user as one line naming the file and the entry, exit 2: not a traceback, not
    "internal error"."""
    copy = tmp_path / "pkg"
    shutil.copytree(PACKAGE, copy / "eyeq_spi", symlinks=False,
                    ignore=shutil.ignore_patterns("__pycache__"))
    capture = copy / "eyeq_spi" / "specs" / "capture.yaml"
    text = capture.read_text()
    assert "link_type: 147" in text
    capture.write_text(text.replace("link_type: 147", "link_type: 1", 1))
    env = {**os.environ, "PYTHONPATH": str(copy), "EYEQ_SPI_CACHE_DIR": str(tmp_path / "cache")}
    r = subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "wireshark"], cwd=tmp_path,
                       env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stdout == "", r.stderr
    assert r.stderr.count("\n") == 1 and "internal error" not in r.stderr, r.stderr
    assert "specs/capture.yaml capture.link_type" in r.stderr, r.stderr
