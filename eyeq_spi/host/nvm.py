"""The host's non-volatile memory, as a JSON file written atomically (temp file, fsync, rename,
fsync of the directory), so a crash at any point leaves either the old or the new file.

The camera alignment it keeps is the §21 Alignment NVM table: its parameters, defaults and the
rules for updating them come from ``specs/nvm.yaml``
(:func:`eyeq_spi.catalog.tables.alignment_nvm`), not from this module."""

from __future__ import annotations

import contextlib
import glob
import json
import math
import os
import re
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from eyeq_spi.catalog.tables import alignment_nvm
from eyeq_spi.errors import OutputError


def alignment_defaults() -> dict[str, float]:
    """The §21 Alignment NVM parameters (``horizonKA``, ``yawKA``, ``rollAngleKA``,
    ``cameraAlignmentValidKA``) at their defaults, as ``specs/nvm.yaml`` lists them."""
    return alignment_nvm().defaults()


def _alignment(raw: Any) -> dict[str, float]:
    """The stored alignment: every parameter of the table, a missing one at its default; names
    the table does not have are ignored. A value that is not a finite number is a corrupt NVM."""
    if not isinstance(raw, dict):
        raise ValueError("alignment is not an object")
    out = alignment_defaults()
    for name in out:
        if name in raw:
            value = raw[name]
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(
                    value):
                raise ValueError(f"alignment {name} is {value!r}, not a finite number")
            out[name] = float(value)
    return out


@dataclass
class NvmData:
    intrinsic: dict[str, float] = field(default_factory=dict)  # 0x84 signals; empty = zeros
    alignment: dict[str, float] = field(default_factory=alignment_defaults)  # §21, by name
    ignition_cycles: int = 0
    versions: dict[str, int] = field(default_factory=dict)


TEMP_SUFFIX = ".nvm-tmp"
_OLD_TEMP = re.compile(r"[a-z0-9_]{8}")  # mkstemp's suffix in files written before 0.2


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return False  # our own leftovers: we are not writing now
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # exists, not ours to signal
    return True


def remove_stale_temp_files(path: Path) -> int:
    """Delete the temporary files of NVM writes that were killed before their rename (a
    crash mid-write). A temp file is never read as the NVM; one whose writer is still alive
    is left alone. Returns how many were removed."""
    removed = 0
    prefix = f".{path.name}."
    try:
        candidates = list(path.parent.glob(f"{glob.escape(prefix)}*"))
    except OSError:
        return 0
    for candidate in candidates:
        rest = candidate.name[len(prefix):]
        if rest.endswith(TEMP_SUFFIX):
            pid_text = rest.split(".", 1)[0]
            if pid_text.isdigit() and _alive(int(pid_text)):
                continue
        elif not _OLD_TEMP.fullmatch(rest):
            continue
        with contextlib.suppress(OSError):
            candidate.unlink()
            removed += 1
    return removed


class Nvm:
    """``path=None`` keeps the NVM in memory (tests, the demo without ``--nvm``)."""

    def __init__(self, path: str | os.PathLike[str] | None = None) -> None:
        self.path = Path(path) if path is not None else None
        self.data = NvmData()
        self.writes = 0
        self.load_problem: str | None = None
        self.removed_temp_files = 0

    def load(self) -> NvmData:
        """Read the file; a missing file is a first power-up. A corrupt file is reported in
        ``load_problem`` and treated as empty, which the §7.1.3 flow repairs."""
        self.data = NvmData()
        if self.path is not None:
            self.removed_temp_files = remove_stale_temp_files(self.path)
        if self.path is None or not self.path.exists():
            return self.data
        try:
            raw = json.loads(self.path.read_text(encoding="utf-8"))
            if not isinstance(raw, dict):
                raise ValueError("top level is not an object")
            self.data = NvmData(
                intrinsic={str(k): float(v) for k, v in raw.get("intrinsic", {}).items()},
                alignment=_alignment(raw.get("alignment", {})),
                ignition_cycles=int(raw.get("ignition_cycles", 0)),
                versions={str(k): int(v) for k, v in raw.get("versions", {}).items()},
            )
        except (OSError, ValueError, TypeError) as exc:
            self.load_problem = f"{self.path}: unreadable NVM ({exc}); starting from empty"
            self.data = NvmData()
        return self.data

    def save(self) -> None:
        self.writes += 1
        if self.path is None:
            return
        doc: dict[str, Any] = asdict(self.data)
        text = json.dumps(doc, indent=2, sort_keys=True)
        directory = self.path.parent if str(self.path.parent) else Path(".")
        try:
            directory.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.{os.getpid()}.",
                                       suffix=TEMP_SUFFIX, dir=directory)
            try:
                with os.fdopen(fd, "w", encoding="utf-8") as fh:
                    fh.write(text)
                    fh.flush()
                    os.fsync(fh.fileno())
                os.replace(tmp, self.path)
            except BaseException:
                Path(tmp).unlink(missing_ok=True)
                raise
            dfd = os.open(directory, os.O_RDONLY)
            try:
                os.fsync(dfd)
            finally:
                os.close(dfd)
        except OSError as exc:
            raise OutputError(f"cannot write NVM {self.path}: {exc}") from exc
