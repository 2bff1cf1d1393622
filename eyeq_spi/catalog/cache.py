"""Start-up cache of the validated catalogue (a cache of data, never of code).

The :class:`~eyeq_spi.catalog.messages.Catalog` is pickled, and single files of ``specs/``
(``spec_file``) marshalled so a start from the cache never imports yaml, in the user's cache
directory under a key over the path, size and mtime of every file of ``specs/`` and of the
loaders, and the Python version (:func:`specs_digest`). An unusable cache falls back to parsing
``specs/``. ``EYEQ_SPI_CACHE_DIR`` moves it, ``EYEQ_SPI_NO_CACHE=1`` turns it off; files are
read only from the current user's, written atomically."""

from __future__ import annotations

import contextlib
import marshal
import os
import re
import sys
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

T = TypeVar("T")

_FORMAT = b"eyeq-spi catalogue cache 1"


def cache_dir() -> Path:
    """``$EYEQ_SPI_CACHE_DIR``, else the platform's user cache directory + ``eyeq-spi``."""
    env = os.environ.get("EYEQ_SPI_CACHE_DIR")
    if env:
        return Path(env)
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("eyeq-spi", appauthor=False))


def specs_digest(root: Path) -> str:
    """A key over the path, size and modification time (ns) of every file of ``root`` and of the
    loader sources, the root and the Python version: the test Python's own bytecode cache makes
    (an edited file has a new mtime), from one ``stat`` per file and no file read, so a start
    spends 0.2 ms here instead of 7 ms hashing every byte. 64 bits (CRC-32, Adler-32)."""
    sig = [_FORMAT.decode(), sys.version, str(root.resolve())]
    sig += _stat_tree(Path(__file__).resolve().parent, ".py") + _stat_tree(root, "")
    text = "\0".join(sig).encode()
    return f"{zlib.crc32(text):08x}{zlib.adler32(text):08x}"


def _stat_tree(top: Path, suffix: str) -> list[str]:
    out: list[str] = []
    with os.scandir(top) as it:
        for entry in it:
            if entry.is_dir(follow_symlinks=False):
                if entry.name != "__pycache__":
                    out += _stat_tree(Path(entry.path), suffix)
            elif entry.name.endswith(suffix):
                st = entry.stat()
                out.append(f"{entry.path}\1{st.st_size}\1{st.st_mtime_ns}")
    return sorted(out)


_DIGESTS: dict[Path, str] = {}  # root -> digest, once per process (as spec_file's own cache)


def cached_catalog(root: Path, load: Callable[[Path], T]) -> T:
    """``load(root)``, or the pickled result of an earlier call with the same ``specs/``."""
    if os.environ.get("EYEQ_SPI_NO_CACHE"):
        return load(root)
    try:
        digest = _DIGESTS[root] = specs_digest(root)  # always afresh; single files reuse it
        path = cache_dir() / f"catalog-{digest[:32]}.pickle"
    except (OSError, ImportError):
        return load(root)
    cached = _read(path)
    if cached is not None:
        return cast(T, cached)
    value = load(root)  # a SpecError propagates: nothing is cached for a broken specs/
    _write(path, value)
    return value


def cached_data(root: Path, tag: str, build: Callable[[], dict[str, Any]]) -> dict[str, Any]:
    """``build()`` (plain data derived from ``specs/`` only), or its marshalled copy from an
    earlier call with the same ``specs/`` and ``tag``. A caller whose data also depends on its own
    code puts a format version in ``tag``."""
    if os.environ.get("EYEQ_SPI_NO_CACHE"):
        return build()
    try:
        digest = _DIGESTS.get(root) or _DIGESTS.setdefault(root, specs_digest(root))
        path = cache_dir() / f"doc-{digest[:32]}-{re.sub(r'[^A-Za-z0-9_.-]', '_', tag)}.marshal"
    except (OSError, ImportError):
        return build()
    cached = _read(path, _unmarshal)
    if isinstance(cached, dict):
        return cached
    value = build()
    _write(path, value, marshal.dump, f"doc-{digest[:32]}-")
    return value


def _unmarshal(fh: Any) -> object:
    """``marshal.load`` reads a file object a few bytes per value: one read, then ``loads``."""
    return marshal.loads(fh.read())


def _read(path: Path, reader: Callable[[Any], object] | None = None) -> object | None:
    if reader is None:
        import pickle  # not for the marshal files: a usage error never imports it

        reader = pickle.load
    try:
        st = path.stat()
        if hasattr(os, "getuid") and st.st_uid != os.getuid():
            return None  # only trust a file this user wrote
        with path.open("rb") as fh:
            value: object = reader(fh)
            return value
    except FileNotFoundError:
        return None
    except Exception:  # a corrupt, foreign or unpicklable cache is never fatal
        with contextlib.suppress(OSError):
            path.unlink()
        return None


KEEP_KEYS = 16  # other keys' files kept: several installs, checkouts or Pythons of one user


def _write(path: Path, value: object, writer: Callable[[Any, Any], object] | None = None,
           current: str = "") -> None:
    """Write atomically; then keep the files of the ``KEEP_KEYS`` newest other keys only, so that
    several installs of one user keep their own caches instead of evicting each other's."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        import tempfile  # only to write: a start from the cache does not import it (nor random)

        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".catalog-", suffix=".tmp")
    except OSError:
        return  # read-only home, full disk...: run without a cache
    try:
        with os.fdopen(fd, "wb") as fh:
            if writer is None:
                import pickle

                pickle.dump(value, fh, protocol=pickle.HIGHEST_PROTOCOL)
            else:
                writer(value, fh)  # marshal: ValueError for a type it cannot hold
        os.replace(tmp, path)
        _prune(path.parent, "catalog-" if writer is None else "doc-", current or path.name)
    except Exception:  # a corrupt, foreign or unpicklable cache is never fatal
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def _prune(folder: Path, kind: str, current: str) -> None:
    """Remove the files of ``kind`` whose key is not among the ``KEEP_KEYS`` newest other keys
    (by the newest modification time of the key's files); never those starting with
    ``current``."""
    newest: dict[str, float] = {}
    files: dict[str, list[Path]] = {}
    for path in folder.glob(f"{kind}*"):
        if path.name.startswith(current):
            continue
        key = path.name[len(kind) : len(kind) + 32].split("-")[0].split(".")[0]
        with contextlib.suppress(OSError):
            newest[key] = max(newest.get(key, 0.0), path.stat().st_mtime)
            files.setdefault(key, []).append(path)
    for key in sorted(newest, key=newest.__getitem__, reverse=True)[KEEP_KEYS:]:
        for path in files[key]:
            with contextlib.suppress(OSError):
                path.unlink()
