"""The reference/fast switch shared by every family of fast leaves.

Where a hot path has a faster twin (numpy, ``struct``, a packed buffer), the
pure-Python one is the reference: it is what the seed says, and the fast one is held to give
the same output (``tests/test_twins.py``). A facade picks the fast twin unless
``EYEQ_SPI_EXACT=1`` is set in the environment; then every family runs its reference.

The convention (``docs/STYLE.md``): ``<name>_ref.py`` the reference, ``<name>_fast.py`` the
fast twin, ``<name>_types.py`` the vocabulary both share, and ``<name>.py`` the facade the rest
of the code imports. :data:`FAMILIES` lists them; each is here because a floor of
``docs/performance.md`` needs it (the emulator's real-time factor, ``dissect --stats``).
"""

from __future__ import annotations

import os

EXACT_ENV = "EYEQ_SPI_EXACT"
"""Set to 1 (any value but empty or 0): every facade picks its reference."""


def references_only() -> bool:
    """True when the environment asks for the references. Read at each call (cheap), so a
    test or a tool may set the variable for one run."""
    return os.environ.get(EXACT_ENV, "").strip() not in ("", "0")


FAMILIES: dict[str, tuple[str, str]] = {
    # family: (reference, fast twin); the facade is the family's module
    "codec.layout": ("construct codec (Layout.parse_construct)", "eyeq_spi.codec.layout_fast"),
    "codec.message": ("Layout.parse per message", "eyeq_spi.codec.message_fast"),
    # the one Dissector (feed); the fast leaf checks frames over arrays and hands clean runs'
    # messages to Dissector.accept_clean; eyeq_spi.dissect.pipeline.fast_module chooses
    "dissect.engine": ("eyeq_spi.dissect.engine", "eyeq_spi.dissect.engine_fast"),
    # python-pcapng, or array chunks read once with the release (pipeline_fast.open_fast)
    "capture.pcapng": ("eyeq_spi.capture.pcapng_io", "eyeq_spi.capture.pcapng_fast"),
    "sim.dasp": ("a value dict through MessageCodec.encode_dasp", "eyeq_spi.sim.dasp_fast"),
}
