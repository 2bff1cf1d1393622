"""Start ``eyeq-spi sim`` (or any command that prints ``LISTEN URL`` / ``PTY PATH`` on stderr)
as a separate process and read the address it serves, within a wall-time bound."""

from __future__ import annotations

import queue
import subprocess
import sys
import threading
from pathlib import Path
from typing import IO

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "eyeq_spi.cli"]


def read_address(stream: IO[str], timeout: float = 60.0) -> tuple[str, str, list[str]]:
    """(kind, address, lines before it) from the first ``LISTEN``/``PTY`` line of ``stream``;
    AssertionError with what was read if none comes within ``timeout`` seconds (a loaded
    machine may take a while to import and warm up). A daemon thread reads, so a silent
    process cannot hang the test; it stops reading at the address line."""
    seen: list[str] = []
    found: queue.Queue[tuple[str, str]] = queue.Queue()

    def read() -> None:
        for line in stream:
            part = line.split()
            if len(part) == 2 and part[0] in ("LISTEN", "PTY"):
                found.put((part[0], part[1]))
                return
            seen.append(line)

    threading.Thread(target=read, daemon=True).start()
    try:
        kind, url = found.get(timeout=timeout)
    except queue.Empty:
        raise AssertionError(f"no LISTEN/PTY line within {timeout} s: {''.join(seen)!r}") \
            from None
    return kind, url, seen


def start_sim(*args: str) -> tuple[subprocess.Popen[str], str]:
    """``eyeq-spi sim ARGS`` with stdout (the summary) and stderr piped, and its address."""
    sim = subprocess.Popen([*CLI, "sim", *args], cwd=ROOT, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    assert sim.stderr is not None
    try:
        _, url, _ = read_address(sim.stderr)
    except AssertionError:
        sim.kill()
        sim.wait(timeout=10)
        raise
    return sim, url
