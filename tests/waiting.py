"""Waiting on another thread or process: the one polling loop of the tests.

Timers are tested on an injected clock; what is left for wall time is waiting until another
thread or process has done something (a file written, a transfer read), bounded so that a
loaded machine is slower but never hangs a test."""

from __future__ import annotations

import time
from collections.abc import Callable


def wait_until(done: Callable[[], object], timeout: float, what: str) -> None:
    """Poll ``done`` every 5 ms until it is true; fail saying ``what`` after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, f"{what}: not within {timeout} s"
        time.sleep(0.005)
