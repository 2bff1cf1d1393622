"""``eyeq-spi sigrok-decoder --install DIR``: copy the ``eyeq_spi`` decoder where
libsigrokdecode looks for decoders, with a ``_site.py`` telling its embedded Python where this
project and its dependencies are installed."""

from __future__ import annotations

import os
import shutil
import site
import sys
from pathlib import Path

import eyeq_spi
from eyeq_spi.errors import OutputError

DECODER_FILES = ("__init__.py", "pd.py")


def decoder_source() -> Path:
    return Path(__file__).resolve().parent / "sigrok" / "decoder"


def default_dir() -> Path:
    """libsigrokdecode's user decoder folder (``$XDG_DATA_HOME/libsigrokdecode/decoders``)."""
    base = os.environ.get("XDG_DATA_HOME") or os.path.join(Path.home(), ".local", "share")
    return Path(base) / "libsigrokdecode" / "decoders"


def import_paths() -> list[str]:
    """The folder holding this project's package, then this interpreter's site-packages (the
    project's dependencies), for the embedded interpreter of libsigrokdecode."""
    out = [str(Path(eyeq_spi.__file__).resolve().parent.parent)]
    sites = [*site.getsitepackages(), site.getusersitepackages()]
    for site_dir in sites:
        if site_dir not in out and os.path.isdir(site_dir):
            out.append(site_dir)
    return out


def install(directory: str | Path | None = None) -> Path:
    """Write ``DIR/eyeq_spi/`` and return it."""
    dest = Path(directory) if directory else default_dir()
    target = dest / "eyeq_spi"
    try:
        target.mkdir(parents=True, exist_ok=True)
        for name in DECODER_FILES:
            shutil.copyfile(decoder_source() / name, target / name)
        lines = ['"""Written by eyeq-spi sigrok-decoder --install: where eyeq-spi and its',
                 f'dependencies are installed (Python {sys.version.split()[0]})."""', "",
                 "PATHS = ["]
        lines += [f"    {p!r}," for p in import_paths()]
        lines += ["]", ""]
        (target / "_site.py").write_text("\n".join(lines), encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"cannot install the decoder in {dest}: {exc.strerror or exc}") \
            from None
    return target
