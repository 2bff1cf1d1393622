"""Coverage-guided run of one in-process target under atheris (libFuzzer):

    python -m tests.fuzz.atheris_main TARGET FIGURES.json [libFuzzer options...]

``eyeq_spi`` is instrumented for coverage. A Finding, a Hang or any other exception ends the run
with libFuzzer's crash report and an artifact (``-artifact_prefix``). The figures (inputs,
frames, messages) are written to FIGURES.json every second, since libFuzzer leaves through
``exit()`` without running Python's exit handlers."""

from __future__ import annotations

import json
import sys
import time

import atheris

with atheris.instrument_imports(include=["eyeq_spi"]):
    from tests.fuzz.core import FIGURES
    from tests.fuzz.registry import TARGETS


def main() -> None:
    name, figures = sys.argv[1], sys.argv[2]
    target = TARGETS[name]
    next_dump = [0.0]

    def dump() -> None:
        with open(figures, "w", encoding="utf-8") as fh:
            json.dump(dict(FIGURES), fh)

    def one(data: bytes) -> None:
        FIGURES["inputs"] += 1
        try:
            target(data)
        finally:
            now = time.monotonic()
            if now >= next_dump[0]:
                next_dump[0] = now + 1.0
                dump()

    atheris.Setup([sys.argv[0], *sys.argv[3:]], one)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
