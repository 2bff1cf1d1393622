"""What ``--help`` shows beyond the options: a description for every command and 2-3 examples
(an argparse epilog, kept as written by :class:`HelpFormatter`; descriptions are
wrapped here to the terminal instead). Every example is a command that parses
(``tests/test_cli_progress.py``)."""

from __future__ import annotations

import argparse
import shutil
import textwrap
from typing import Any

TOP_DESCRIPTION = (
    "The host side of the EyeQ4 SPI interface and its Mobileye CAN output: a simulated EyeQ "
    "and a host emulator to run against each other or against real hardware, a dissector for "
    "captures (terminal, JSON, tables, Wireshark, PulseView), plots, a live monitor and a "
    "conformance suite. Every wire format comes from specs/.")

TOP_EXAMPLES = [
    "eyeq-spi demo --duration 5                       # a simulated EyeQ up, 5 s",
    "eyeq-spi demo --virtual-time --capture x.pcapng  # 10 s captured, fast",
    "eyeq-spi dissect x.pcapng --stats                # what the capture holds",
]

# command (subcommands as "can dbc") -> (description when it has none, examples)
EXAMPLES: dict[str, list[str]] = {
    "demo": [
        "eyeq-spi demo --duration 5",
        "eyeq-spi demo --virtual-time --duration 60 --capture run.pcapng",
        "eyeq-spi demo --virtual-time --stop-dasp EYEQ_VIS_SRP_MSG@3 --json",
    ],
    "sim": [
        "eyeq-spi sim --listen tcp://127.0.0.1:0       # prints LISTEN tcp://HOST:PORT",
        "eyeq-spi sim --pty --duration 60",
    ],
    "host": [
        "eyeq-spi host --port tcp://127.0.0.1:5000 --duration 10",
        "eyeq-spi host --port rfc2217://192.168.1.20:4000 --exit-when-running --json",
    ],
    "dissect": [
        "eyeq-spi dissect capture.pcapng --id 0xE4 --no-tree",
        "eyeq-spi dissect capture.pcapng --stats",
        "eyeq-spi dissect capture.pcapng --json | jq -c 'select(.kind==\"message\")'",
    ],
    "wireshark": [
        "eyeq-spi wireshark -o eyeq_spi.lua",
        "wireshark -X lua_script:eyeq_spi.lua capture.pcapng",
    ],
    "batch": [
        "eyeq-spi batch captures/ --parquet dataset/",
        "eyeq-spi batch captures/ --parquet dataset/ --jobs 4",
    ],
    "can": [
        "eyeq-spi can dbc --output dbc/",
        "eyeq-spi can decode drive.blf --stats",
    ],
    "can dbc": [
        "eyeq-spi can dbc --output dbc/",
        "eyeq-spi can dbc --protocol me8 --output dbc/",
    ],
    "can decode": [
        "eyeq-spi can decode drive.blf --channel 1 --stats",
        "eyeq-spi can decode drive.asc --protocol me8 --json",
        "eyeq-spi can decode --bus socketcan:can0 --duration 10",
    ],
    "can compare": [
        "eyeq-spi can compare vendor.dbc",
        "eyeq-spi can compare vendor.dbc --json",
    ],
    "plot": [
        "eyeq-spi plot capture.pcapng --birdseye --at 4 -o scene.png",
        "eyeq-spi plot capture.pcapng --timing --name 'OBSTACLES|SRP' -o timing.html",
        "eyeq-spi plot capture.pcapng --link -o link.svg",
    ],
    "monitor": [
        "eyeq-spi monitor --demo --duration 30",
        "eyeq-spi monitor --replay capture.pcapng --pace 4",
        "eyeq-spi monitor --port tcp://127.0.0.1:5000",
    ],
    "export": [
        "eyeq-spi export capture.pcapng --vcd capture.vcd",
        "eyeq-spi export capture.pcapng --mdf capture.mf4 --mcap capture.mcap",
    ],
    "replay": [
        "eyeq-spi replay capture.pcapng --into-host",
        "eyeq-spi replay capture.pcapng --listen tcp://127.0.0.1:5000",
    ],
    "sigrok-decoder": [
        "eyeq-spi sigrok-decoder --install",
        "eyeq-spi sigrok-decoder --install decoders/",
    ],
    "conformance": [
        "eyeq-spi conformance --builtin --dut eyeq",
        "eyeq-spi conformance --dut eyeq --port tcp://127.0.0.1:5000 --junit results.xml",
        "eyeq-spi conformance --list",
    ],
    "spec": [
        "eyeq-spi spec list",
        "eyeq-spi spec show 0xE4",
    ],
    "spec list": [
        "eyeq-spi spec list",
        "eyeq-spi spec list --sw 8.1",
    ],
    "spec show": [
        "eyeq-spi spec show EYEQ_VIS_OBSTACLES_MSG",
        "eyeq-spi spec show 0xE4 --sw 8.1",
    ],
    "bench": [
        "eyeq-spi bench doctor ft4222://0,ft4222://1     # master looped to slave",
        "eyeq-spi bench doctor ft4222://0,ft4222://1 --peer ft4222://2,ft4222://3",
    ],
    "bench doctor": [
        "eyeq-spi bench doctor spidev:///dev/spidev0.0,spidev:///dev/spidev1.0",
        "eyeq-spi bench doctor ft4222://0,ft4222://1 --frames 1000 --json",
        "eyeq-spi bench doctor ft4222://0,ft4222://1 --peer ft4222://2,ft4222://3",
    ],
}


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """argparse's help with descriptions and examples kept as written, and an option that takes
    a value listed as ``-j, --jobs N`` (its metavar once, as Python 3.13 and later print it)
    on every Python: Python 3.11 and 3.12 print ``-j N, --jobs N``. So ``--help`` reads the
    same everywhere, and docs/cli.md (generated from it) matches every supported Python."""

    def _format_action_invocation(self, action: argparse.Action) -> str:
        if not action.option_strings:
            return super()._format_action_invocation(action)
        if action.nargs == 0:
            return ", ".join(action.option_strings)
        metavar = self._format_args(action, self._get_default_metavar_for_optional(action))
        return f"{', '.join(action.option_strings)} {metavar}"

    def _format_usage(self, usage: str | None, actions: Any, groups: Any,
                      prefix: str | None) -> str:
        """The usage line as argparse makes it, wrapped here: each bracketed option or group
        whole, filled up to the width. Python 3.13 wraps inside a group of exclusive options
        where 3.11 does not; this wraps the same on every Python."""
        width = self._width
        self._width = 1 << 30  # one line: argparse's own wrapping differs between releases
        try:
            text = super()._format_usage(usage, actions, groups, prefix).strip("\n")
        finally:
            self._width = width
        head = f"{'usage: ' if prefix is None else prefix}{self._prog}"
        if not text.startswith(head):
            return f"{text}\n\n"
        units = _usage_units(text[len(head):])
        lines, indent = [head], len(head) + 1
        if indent > 0.75 * width and units:  # a long program name: the options go below it
            indent = len("usage: " if prefix is None else prefix)
            lines.append(" " * indent + units.pop(0))
        for unit in units:
            if len(lines[-1]) + 1 + len(unit) > width and lines[-1] != head:
                lines.append(" " * indent + unit)
            else:
                lines[-1] += " " + unit
        return "\n".join(lines) + "\n\n"


def _usage_units(text: str) -> list[str]:
    """``text`` split at the spaces outside brackets and parentheses."""
    units: list[str] = []
    depth, start = 0, None
    for index, ch in enumerate(text + " "):
        if ch in "[(":
            depth += 1
        elif ch in "])":
            depth = max(0, depth - 1)
        if ch == " " and depth == 0:
            if start is not None:
                units.append(text[start:index])
                start = None
        elif start is None:
            start = index
    return units


def _width() -> int:
    return max(40, min(shutil.get_terminal_size((80, 24)).columns, 100) - 2)


def finish(parser: argparse.ArgumentParser, name: str = "", help_line: str = "",
           width: int | None = None) -> None:
    """Give ``parser`` and every subcommand parser under it a description wrapped at ``width``
    (default: the terminal's) and their examples. Cheap: it touches only the parsers that
    exist (main builds one command's)."""
    parser.formatter_class = HelpFormatter
    desc = parser.description or help_line or ""
    if not name:
        desc = TOP_DESCRIPTION
    width = width or _width()
    parser.description = "\n\n".join(textwrap.fill(" ".join(p.split()), width)
                                      for p in desc.split("\n\n")) if desc else None
    examples = TOP_EXAMPLES if not name else EXAMPLES.get(name)
    if examples:
        parser.epilog = "examples:\n" + "\n".join(f"  {line}" for line in examples)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or "" for a in action._choices_actions}
            for sub_name, sub in action.choices.items():
                finish(sub, f"{name} {sub_name}".strip(), helps.get(sub_name, ""), width)
