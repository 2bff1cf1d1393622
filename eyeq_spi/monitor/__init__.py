"""``eyeq-spi monitor``: a live terminal view of ``demo``, ``host`` or a replayed capture.

Three sources (:mod:`.sources`) advance the protocol and produce a :class:`.model.Snapshot`;
:mod:`.view` draws a snapshot with rich; :mod:`.app` alternates the two so that the screen is
redrawn at ``--refresh`` Hz (6 by default, 5 at least). The sources read the host only through
its public face (``subscribe``, ``state``, ``transitions``, counters) and the capture only
through the dissector engine: nothing here threads through the host or the simulator.
"""

from __future__ import annotations
