"""The cyclic garbage collector, managed in this one place.

A pass over the older generations walks every object alive. The real-time runner cannot afford
one mid-burst (a full pass takes about as long as the peer's 10 ms ``ackTimeout``), and long
reads re-scanned records under construction (a third of the CPU of ``dissect --json``). Both hold
:func:`paused` while they run and call :func:`collect` when they choose; memory stays bounded."""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator


@contextlib.contextmanager
def paused(*, freeze: bool = False) -> Iterator[None]:
    """The automatic collector off while the block runs, then as it was. ``freeze``: first
    collect, then keep everything built so far out of every later pass (the catalogue, codecs and
    scene of a real-time run) until the outermost freezing block ends."""
    was = gc.isenabled()
    thaw = freeze and gc.get_freeze_count() == 0
    if freeze:
        gc.collect()
        gc.freeze()
    gc.disable()
    try:
        yield
    finally:
        if thaw:
            gc.unfreeze()
        if was:
            gc.enable()


def collect(grown: int = 0, full: bool = False) -> None:
    """Collect the young generations (with ``full``, every generation) if the youngest has grown
    by at least ``grown`` containers since the last pass."""
    if gc.get_count()[0] >= grown:
        gc.collect(2 if full else 1)
