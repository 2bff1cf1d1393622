"""Subprocess side of the dissect target: ``python -m tests.fuzz.dissect_driver LIMIT
FORMAT:FILE...`` runs ``eyeq-spi dissect --format FORMAT --json FILE`` for each file through the
CLI's own entry point, with LIMIT seconds per file, and prints one JSON line per file."""

from __future__ import annotations

import contextlib
import io
import json
import os
import sys

from eyeq_spi.cli import main

from .core import Hang, time_limit


def run(limit: float, files: list[str]) -> None:
    out = sys.stdout
    for item in files:
        fmt, _, path = item.partition(":")
        err = io.StringIO()
        hang = False
        rc: int | None = None
        with open(os.devnull, "w") as sink, contextlib.redirect_stdout(sink), \
                contextlib.redirect_stderr(err):
            try:
                with time_limit(limit):
                    rc = main(["dissect", "--format", fmt, "--json", path])
            except Hang:
                hang = True
            except SystemExit as exc:
                rc = exc.code if isinstance(exc.code, int) else 2
            except BaseException as exc:  # the CLI let an exception through: a finding
                err.write(f"Traceback: {type(exc).__name__}: {exc}\n")
        out.write(json.dumps({"file": path, "rc": rc, "stderr": err.getvalue(),
                              "hang": hang}) + "\n")
        out.flush()


if __name__ == "__main__":
    run(float(sys.argv[1]), sys.argv[2:])
