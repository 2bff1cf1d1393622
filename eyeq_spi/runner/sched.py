"""Real-time scheduling for a live link process.

The link answers every DATA frame within the peer's 10 ms ``ackTimeout`` (L7, §6); under load
the kernel's time-sharing can leave a woken process waiting longer (a live run at load 8-9 on 2
cores lost 186 frames in 30 s, ``tools/soak_live.py``). So ``host`` and ``sim`` ask for
``SCHED_FIFO`` at a modest priority (they sleep in ``select`` between frames, and Linux keeps 5 %
of every core for ordinary tasks); without permission they fall back to the highest ``nice``
they may take, then to ordinary scheduling, reported in the run summary."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

DEFAULT_PRIORITY = 10
"""Of 1..99: above ordinary tasks, below the kernel's own real-time threads (50 and up)."""


def request_realtime(priority: int = DEFAULT_PRIORITY) -> str:
    """Ask for ``SCHED_FIFO`` at ``priority`` (0: leave scheduling alone); returns what was
    obtained (``"SCHED_FIFO 10"``, ``"nice -10"`` or ``"SCHED_OTHER"`` with the reason). Forked
    children start with ordinary scheduling (``SCHED_RESET_ON_FORK``)."""
    if priority <= 0:
        return "SCHED_OTHER (not requested)"
    if not hasattr(os, "sched_setscheduler"):  # not Linux
        return "SCHED_OTHER (no sched_setscheduler on this platform)"
    try:
        policy = os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)
        os.sched_setscheduler(0, policy, os.sched_param(priority))
        return f"SCHED_FIFO {priority}"
    except (PermissionError, OSError) as exc:
        reason = exc.strerror or type(exc).__name__
    try:
        before = os.nice(0)
        after = os.nice(-10)
        if after < before:
            return f"nice {after} (SCHED_FIFO refused: {reason})"
    except OSError:
        pass
    return f"SCHED_OTHER (SCHED_FIFO refused: {reason})"


@contextlib.contextmanager
def realtime(priority: int = DEFAULT_PRIORITY) -> Iterator[str]:
    """:func:`request_realtime` for a live run, then the previous policy and nice value again (a
    process left at ``SCHED_FIFO`` would starve every ordinary task while it computes)."""
    if priority <= 0 or not hasattr(os, "sched_getscheduler"):
        yield request_realtime(priority)
        return
    policy, param, nice = os.sched_getscheduler(0), os.sched_getparam(0), os.nice(0)
    try:
        yield request_realtime(priority)
    finally:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, policy, param)
        with contextlib.suppress(OSError):
            now = os.nice(0)
            if now != nice:
                os.nice(nice - now)
