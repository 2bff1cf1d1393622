"""The cyclic garbage collector, managed in this one place.

Python's automatic cyclic collector runs whenever 700 more containers have been made than freed,
and a pass over the older generations walks every object alive. Two kinds of run cannot afford
that at a moment they do not choose:

- the real-time runner (:mod:`eyeq_spi.runner.realtime`): a full pass can take about 10 ms, as
  long as the peer's ``ackTimeout``, so a pass in the middle of a burst costs retransmissions.
  The runner collects the young generations itself when nothing is due for a while;
- long reads (the dissect pipeline, the captures a plot or a view collects): records are trees
  of dicts and lists, and the automatic passes re-scanned records under construction (a third of
  the CPU of ``dissect --json``). The reader collects the young generations between records.

Both hold :func:`paused` while they run and call :func:`collect` when they choose. Records
are freed by reference counts as ever; a cycle is still freed at the next chosen pass, so memory
stays bounded. Nothing else in the package touches the collector.
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator


@contextlib.contextmanager
def paused(*, freeze: bool = False) -> Iterator[None]:
    """The automatic collector off while the block runs; on again after, if it was on (nested
    blocks and a caller that had it off keep their state). ``freeze``: first collect, then move
    everything built so far out of every later collection (the catalogue, codecs and scene of a
    real-time run), so that no later pass, not even a full one, walks them. The outermost
    freezing block gives them back to the collector when it ends."""
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
