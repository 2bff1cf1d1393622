"""The CLI reference (docs/cli.md) is generated from the argparse definitions, never stale."""

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


def test_cli_reference_is_current() -> None:
    tool = _tool()
    readme = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    assert tool.splice(readme, tool.render()) == readme, (
        "docs/cli.md is stale: run python tools/cli_reference.py")


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
    readme = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    head, _, tail = readme.partition(tool.BEGIN)
    stale = head + tool.BEGIN + tail.replace("--virtual-time", "--virtual-tyme", 1)
    assert stale != readme
    assert tool.splice(stale, tool.render()) != stale


def test_readme_docs_and_specs_point_at_nothing_outside_the_repository() -> None:
    """A clone has no ../shared: README, docs/ and specs/ restate what they need."""
    import re

    outside = re.compile(r"\.\./shared|(?<![\w.-])shared/(seeds|PROTOCOL)|/work/")
    paths = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")),
             *sorted(p for p in (ROOT / "specs").rglob("*") if p.suffix in (".md", ".yaml"))]
    hits = [f"{p.relative_to(ROOT)}:{n}: {line.strip()}" for p in paths
            for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
            if outside.search(line)]
    assert len(paths) > 20 and hits == []
    assert outside.search("see ../shared/PROTOCOL_DECISIONS.md")  # the pattern can match


def test_help_is_formatted_the_same_on_every_python() -> None:
    """``--help`` (and so docs/cli.md) must not depend on the Python release: an option's
    metavar once (``-o, --output FILE``, Python 3.13's form; 3.11 prints ``-o FILE, --output
    FILE``), and the usage filled with each bracketed option or group whole (3.13 wraps inside
    a group of exclusive options, 3.11 does not)."""
    import argparse

    from eyeq_spi.cli.help import HelpFormatter, _usage_units

    p = argparse.ArgumentParser(prog="eyeq-spi batch", formatter_class=lambda prog: HelpFormatter(
        prog, width=72))
    p.add_argument("-o", "--output", metavar="FILE")
    p.add_argument("--jobs", "-j", type=int, metavar="N")
    p.add_argument("--quiet", "-q", action="store_true")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--port", metavar="URL")
    g.add_argument("--listen", metavar="tcp://HOST:PORT")
    g.add_argument("--pty", action="store_true")
    p.add_argument("dir", metavar="DIR")
    text = p.format_help()
    assert "  -o, --output FILE" in text and "  --jobs, -j N" in text
    assert "  --quiet, -q" in text
    usage = text.split("\n\n")[0].splitlines()
    assert usage[0].startswith("usage: eyeq-spi batch [-h] [-o FILE]")
    assert any(line.strip() == "[--port URL | --listen tcp://HOST:PORT | --pty]"
               or "[--port URL | --listen tcp://HOST:PORT | --pty]" in line for line in usage)
    assert all(len(line) <= 72 for line in usage)
    assert all(line.startswith(" " * len("usage: eyeq-spi batch ")) for line in usage[1:])
    assert _usage_units(" [-h] [--a X [--b]] (--c | --d) DIR [DIR ...]") == [
        "[-h]", "[--a X [--b]]", "(--c | --d)", "DIR", "[DIR ...]"]
