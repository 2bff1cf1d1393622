"""Real-time scheduling for a live link process.

The link answers every DATA frame within the peer's 10 ms ``ackTimeout`` (L7, §6). On a machine
whose cores are busy with other work, the kernel's ordinary time-sharing (``SCHED_OTHER``) can
leave a woken process waiting longer than that: a live run at load average 8-9 on 2 cores lost
186 frames in 30 s to late ACKs, every one of them a process that was ready but not running
(``tools/soak_live.py``; the README has the figures). A bench emulator is a real-time program, so
``host`` and ``sim`` ask for the ``SCHED_FIFO`` policy at a modest priority, which makes the
kernel run them as soon as they are woken. The processes sleep in ``select`` between frames (about
0.2 CPU-s per second at full load), and Linux keeps 5 % of every core for ordinary tasks
(``sched_rt_runtime_us``), so the rest of the machine is not starved.

Without permission (not root, no ``CAP_SYS_NICE``, no ``RLIMIT_RTPRIO``) the process falls
back to the highest ``nice`` it may take, and then to ordinary scheduling; the policy obtained is
reported in the run summary, never an error.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

DEFAULT_PRIORITY = 10
"""Of 1..99: above ordinary tasks, below the kernel's own real-time threads (50 and up)."""


def request_realtime(priority: int = DEFAULT_PRIORITY) -> str:
    """Ask for ``SCHED_FIFO`` at ``priority`` (0: leave scheduling alone). Returns what was
    obtained: ``"SCHED_FIFO 10"``, ``"nice -10"`` or ``"SCHED_OTHER"`` (with the reason).
    Children forked afterwards start with ordinary scheduling (``SCHED_RESET_ON_FORK``).
    Prefer :func:`realtime`, which gives the policy back when the live run ends."""
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
    """:func:`request_realtime` for the duration of a live run, then the process's previous
    policy and nice value again. A process that runs ``host`` or ``sim`` in-process (a test,
    a notebook) must not stay real-time afterwards: a CPU-bound task at ``SCHED_FIFO`` holds its
    core until it sleeps, which starves every ordinary task and other real-time links."""
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
