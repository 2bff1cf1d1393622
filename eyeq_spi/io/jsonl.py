"""The one JSON Lines writer of every command: one JSON object per line.

``JsonLinesWriter(fh, fast=False).write(record)`` writes ``record`` (a dict of JSON values) as one
line. With ``fast``, orjson encodes, which spells some floats its own way (``2.5e-7`` for
``2.5e-07``, ``0.00005`` for ``5e-05``; the spelling depends on orjson's version, the number does
not). NaN and infinities are ``null`` either way (JSON has no spelling for
them); an integer over 64 bits is written by the standard library's encoder.
"""

from __future__ import annotations

import math
from typing import IO, Any


class JsonLinesWriter:
    """One JSON object per line into the text stream ``fh`` (module docstring)."""

    def __init__(self, fh: IO[str], *, fast: bool = False) -> None:
        import orjson  # here, not at start-up: --stats and the tables never need it

        self.fh = fh
        self.fast = fast
        self._dumps = orjson.dumps
        self._opt = orjson.OPT_APPEND_NEWLINE

    def write(self, record: dict[str, Any]) -> None:
        if self.fast:
            try:
                self.fh.write(self._dumps(record, option=self._opt).decode())
                return
            except TypeError:  # an int over 64 bits: json.dumps writes it (same either way)
                pass
        import json

        try:
            text = json.dumps(record, separators=(",", ":"), allow_nan=False)
        except ValueError:  # NaN/Infinity are not JSON: they become null
            text = json.dumps(_finite(record), separators=(",", ":"), allow_nan=False)
        self.fh.write(text + "\n")


def _finite(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(x) for k, x in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(x) for x in value]
    return value
