"""Command-line interface. Every ``EyeqError`` becomes a one-line message and exit code 2; a
user never sees a traceback for bad input. What ``--help`` shows
beyond the options is in :mod:`eyeq_spi.cli.help`; the options several commands share are in
:mod:`eyeq_spi.cli.options`."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Sequence
from typing import Any

from eyeq_spi import __version__
from eyeq_spi.errors import EyeqError, UsageError


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(message)


# Every command: the module under eyeq_spi/cli/ that adds its parser and runs it, and its
# one-line help, in --help order. A module is imported only for the command that runs (and for
# full --help or a completion script); the other commands are a name and this line, which is all
# --help and a usage error show. Adding a command: one module with add_parser(sub, name, help)
# and run(args), and one row here.
TABLE: dict[str, tuple[str, str]] = {
    "demo": ("run", "host emulator against the embedded simulated EyeQ"),
    "sim": ("run", "the simulated EyeQ on a TCP listener or a pty"),
    "host": ("run", "the host emulator against an EyeQ at --port URL"),
    "dissect": ("dissect", "decode SPI captures (pcapng, raw, hex, Saleae, VCD)"),
    "wireshark": ("wireshark", "generate the Wireshark Lua dissector from specs/"),
    "batch": ("batch", "many captures into one partitioned Parquet dataset"),
    "can": ("can", "Mobileye CAN: DBCs, decode logs or a live bus, compare"),
    "plot": ("plot", "bird's-eye scene, stream timing or link behaviour of a capture"),
    "monitor": ("monitor", "live terminal view of demo, host or a replayed capture"),
    "export": ("export", "a capture as VCD waveforms, MDF4 or MCAP"),
    "replay": ("replay", "play a capture's EyeQ channel to a host"),
    "sigrok-decoder": ("sigrok", "install the eyeq_spi decoder for sigrok/PulseView"),
    "conformance": ("conformance", "protocol conformance suite: verdict per requirement"),
    "spec": ("spec", "browse the message catalogue built from specs/"),
    "bench": ("bench", "check a rig of SPI adapters before a run (bench doctor)"),
}


def command_module(name: str) -> Any:
    """The module of command ``name`` (imported now)."""
    import importlib

    return importlib.import_module(f"eyeq_spi.cli.{TABLE[name][0]}")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The whole parser; with ``only``, the options of that command alone (every other command
    is its name and help line from :data:`TABLE`, enough for ``--help`` and usage errors)."""
    parser = _Parser(prog="eyeq-spi")
    parser.add_argument("--version", action="version", version=f"eyeq-spi {__version__}")
    parser.add_argument("--print-completion", choices=("bash", "zsh", "tcsh"), metavar="SHELL",
                   help="print the shell completion script for SHELL (bash, zsh, tcsh; "
                   "docs/cli.md says where to put it)")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser,
                           title="commands", metavar="COMMAND")
    for name, (_, line) in TABLE.items():
        if only is None or only == name:
            command_module(name).add_parser(sub, name, line)
        else:
            sub.add_parser(name, help=line)
    return parser


def _command(argv: Sequence[str]) -> str:
    """The subcommand ``argv`` names, "" if none (``--print-completion`` takes a value)."""
    rest = [a for k, a in enumerate(argv)
            if k == 0 or argv[k - 1] != "--print-completion"]
    return next((a for a in rest if not a.startswith("-")), "")


def _parser_for(argv: Sequence[str]) -> argparse.ArgumentParser:
    """The parser ``main`` needs: one command's options; with help asked for (or nothing
    given), descriptions and examples too; for a completion script, every command's."""
    parser = build_parser(only=None if "--print-completion" in argv else _command(argv))
    if not argv or "-h" in argv or "--help" in argv:
        from eyeq_spi.cli.help import finish

        finish(parser)
    return parser


def _completion(parser: argparse.ArgumentParser, shell: str) -> int:
    try:
        import shtab
    except ImportError:
        raise UsageError("shell completion needs shtab: pip install shtab") from None
    sys.stdout.write(shtab.complete(parser, shell=shell))
    return 0


# numpy's bundled OpenBLAS starts one spinning thread per core when numpy is imported; no
# command does linear algebra, so that pool only burned CPU (about half of numpy's import cost:
# 0.07 of 0.14 CPU-s on two cores). A value the user set wins; child processes (batch workers)
# inherit it.
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "1")


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command line (``sys.argv[1:]`` by default) and return its exit code: the
    ``eyeq-spi`` script, ``python -m eyeq_spi.cli``, and a library call from tests and
    scripts."""
    os.environ.setdefault(*BLAS_THREADS)
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        parser = _parser_for(argv)
        if not argv:  # bare eyeq-spi: what it is, the commands, examples
            sys.stdout.write(parser.format_help())
            return 0
        if "--print-completion" in argv and _command(argv) == "":
            index = argv.index("--print-completion") + 1
            shell = argv[index] if index < len(argv) else ""
            if shell not in ("bash", "zsh", "tcsh"):
                raise UsageError(f"argument --print-completion: give bash, zsh or tcsh, "
                                 f"not {shell!r}")
            return _completion(parser, shell)
        args = parser.parse_args(argv)
        return int(command_module(args.command).run(args))
    except UsageError as exc:
        return _fail(f"usage error: {exc}")
    except EyeqError as exc:
        return _fail(f"error: {exc}")
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # output piped into head & co.: stop quietly
        return _quiet_pipe()
    except OSError as exc:  # a file or device the user named (disk full, vanished, ...)
        where = f" {exc.filename}" if exc.filename else ""
        return _fail(f"error:{where}: {exc.strerror or exc}")
    except Exception as exc:
        return _fail(f"internal error: {type(exc).__name__}: {exc} (please report this)", 3)


def _fail(message: str, code: int = 2) -> int:
    """One line on stderr, whatever the message holds."""
    from eyeq_spi.cli.args import one_line

    with contextlib.suppress(OSError):  # stderr is gone too
        print(f"eyeq-spi: {one_line(message)}", file=sys.stderr, flush=True)
    return code


def _quiet_pipe() -> int:
    """The reader of stdout went away: point stdout at /dev/null so the interpreter's final
    flush does not print a second error, and exit 0 as head(1)'s writers do."""
    with contextlib.suppress(OSError, ValueError):
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0

