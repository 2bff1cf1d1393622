"""EyeQ4 SPI protocol decoder for libsigrokdecode (PulseView, sigrok-cli), stacked on ``spi``.

It annotates link frames (kind, NUM/RSP, CRC), transport frames and reassembled messages of one
SPI channel with the eyeq-spi project's own codecs (``eyeq_spi.interop.annotate``).

libsigrokdecode imports a decoder as a top-level module named after its folder, so inside
sigrok this package *is* ``eyeq_spi`` and would hide the project of the same name. It therefore
extends its own ``__path__`` with the project's package folder: ``eyeq_spi.codec`` and the rest
then resolve to the project. Where the project lives (and its dependencies' site-packages) is
written to ``_site.py`` by ``eyeq-spi sigrok-decoder --install DIR``; ``EYEQ_SPI_PYTHONPATH`` or
``PYTHONPATH`` may add more folders.
"""

import os
import site
import sys


def _attach_project() -> None:
    here = os.path.dirname(os.path.abspath(__file__))
    paths: list[str] = []
    try:
        from . import _site  # type: ignore[attr-defined]  # written at install time

        paths += list(_site.PATHS)
    except ImportError:
        pass
    paths += [p for p in os.environ.get("EYEQ_SPI_PYTHONPATH", "").split(os.pathsep) if p]
    for p in paths:
        if p not in sys.path and os.path.isdir(p):
            site.addsitedir(p)  # appended: this decoder's folder stays first
    for entry in [*paths, *sys.path]:
        candidate = os.path.join(entry or ".", "eyeq_spi")
        if (os.path.isfile(os.path.join(candidate, "catalog", "link.py"))
                and os.path.realpath(candidate) != os.path.realpath(here)):
            __path__.append(candidate)
            with open(os.path.join(candidate, "__init__.py"), encoding="utf-8") as fh:
                exec(compile(fh.read(), fh.name, "exec"), globals())  # __version__
            return
    raise ImportError("eyeq_spi decoder: the eyeq-spi project is not importable here; "
                      "reinstall with `eyeq-spi sigrok-decoder --install DIR` or set "
                      "EYEQ_SPI_PYTHONPATH")


if __name__ == "eyeq_spi":  # inside libsigrokdecode, not as a part of the installed project
    _attach_project()
    from .pd import Decoder  # noqa: F401
