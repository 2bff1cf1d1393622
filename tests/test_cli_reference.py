"""The README's CLI reference is generated from the argparse definitions and must not be stale."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]


def _tool() -> ModuleType:
    spec = importlib.util.spec_from_file_location("cli_reference", ROOT / "tools" /
                                                  "cli_reference.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["cli_reference"] = mod
    spec.loader.exec_module(mod)
    return mod


def test_readme_cli_reference_is_current() -> None:
    tool = _tool()
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert tool.splice(readme, tool.render()) == readme, (
        "README.md's CLI reference is stale: run python tools/cli_reference.py")


def test_the_reference_covers_every_command_and_option() -> None:
    from eyeq_spi.cli import build_parser

    tool = _tool()
    block = tool.render()
    for parser in tool._walk(build_parser()):
        assert f"#### `{parser.prog}`" in block
        for action in parser._actions:
            for flag in action.option_strings:
                if action.help != "==SUPPRESS==":
                    assert flag in block, (parser.prog, flag)


def test_a_changed_option_makes_the_check_fail() -> None:
    tool = _tool()
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    head, _, tail = readme.partition(tool.BEGIN)
    stale = head + tool.BEGIN + tail.replace("--virtual-time", "--virtual-tyme", 1)
    assert stale != readme
    assert tool.splice(stale, tool.render()) != stale
