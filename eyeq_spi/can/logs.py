"""Reading CAN log files through python-can's readers, and telling a truncated log from a
complete one.

python-can's readers stop quietly at the end of what a file holds: a BLF cut inside a container,
an ASC, candump or TRC file cut inside a line gives the frames before the cut and no error. So
after the reader ends, :func:`read_log` checks the file itself: a BLF whose header announces more
bytes than the file has, a text log whose last line has no line end (or an ASC without its
``End TriggerBlock``), an MF4 whose blocks or links reach beyond its end. It then raises
:class:`TruncatedInputError`, which says how much was read; the frames before it have been
yielded (and decoded) already.
"""

from __future__ import annotations

import logging
import re
import struct
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from eyeq_spi.can.dbc import require_cantools
from eyeq_spi.errors import (
    AdapterError,
    EyeqError,
    InputError,
    MissingExtra,
    TruncatedInputError,
    UsageError,
)

READ_SUFFIXES = (".blf", ".asc", ".log", ".trc", ".mf4", ".csv")
TEXT_SUFFIXES = (".asc", ".log", ".trc", ".csv")
FORMAT_NAMES = {".blf": "BLF", ".asc": "ASC", ".log": "candump", ".trc": "TRC", ".mf4": "MF4",
                ".csv": "python-can CSV"}
# how each format's file begins: a file that does not begin so never was that format (exit 2);
# one that does and then ends inside a record is truncated (exit 1). The text formats are recognised
# by their first line, which a cut file keeps (or keeps the start of).
_ASC_HEAD = re.compile(rb"(date|base|internal events|begin triggerblock|//|\s*\d+\.\d+\s)",
                       re.I)
_CANDUMP_HEAD = re.compile(rb"\(\d")
_TRC_HEAD = re.compile(rb"(;|\s*\d+\)?\s+\d)")
_CSV_HEAD = b"timestamp,arbitration_id"
_MF4_BLOCK = re.compile(rb"##[A-Z]{2}")


def _looks_like(head: bytes, suffix: str) -> bool:
    """Whether ``head`` (the file's first bytes) begins as a ``suffix`` log."""
    if suffix == ".blf":
        return head[:4] == b"LOGG"
    if suffix == ".mf4":
        return head[:8] in (b"MDF     ", b"UnFinMF ")
    if b"\0" in head:  # the text formats: never a NUL byte
        return False
    first = head.lstrip(b"\xef\xbb\xbf").lstrip(b"\r\n")
    if suffix == ".asc":
        return _ASC_HEAD.match(first) is not None
    if suffix == ".log":
        return _CANDUMP_HEAD.match(first) is not None
    if suffix == ".trc":
        return _TRC_HEAD.match(first) is not None
    return _CSV_HEAD.startswith(first[:len(_CSV_HEAD)]) or first.startswith(_CSV_HEAD)


def _check_format(path: Path, suffix: str) -> None:
    """:class:`InputError` for a directory, a missing file or one that never was ``suffix``'s
    format (an empty file passes: it holds no frames)."""
    if path.is_dir():
        raise InputError(f"{path}: a directory, not a CAN log (give its log files, e.g. "
                          f"{path}/*.blf)")
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        with path.open("rb") as fh:
            head = fh.read(512)
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    if head and not _looks_like(head, suffix):
        name = FORMAT_NAMES[suffix]
        raise InputError(f"{path}: not {'an' if name[0] in 'AM' else 'a'} {name} log (it does "
                          f"not begin as one)")


def _blf_announced_size(path: Path) -> int | None:
    """The file size a BLF header announces (0/None when the writer never finished it)."""
    try:
        with path.open("rb") as fh:
            head = fh.read(48)
    except OSError:
        return None
    if len(head) < 48 or head[:4] != b"LOGG":
        return None
    # "LOGG", header size, API number, app id/versions (4 x u8), then file size (u64)
    size: int = struct.unpack_from("<Q", head, 16)[0]
    return size or None


def _text_cut(path: Path, suffix: str) -> str | None:
    """Why a text log looks cut, or None."""
    try:
        with path.open("rb") as fh:
            head = fh.read(4096)
            size = fh.seek(0, 2)
            if size == 0:
                return None
            fh.seek(max(0, size - 4096))
            tail = fh.read()
    except OSError:
        return None
    if not tail.endswith(b"\n"):
        return "its last line has no line end"
    if suffix == ".asc" and b"begin triggerblock" in head.lower():
        # Vector's block: a file that opens it ends with it (converters that write neither,
        # as can-utils' log2asc, are checked by their last line only)
        last = tail.rstrip().rsplit(b"\n", 1)[-1].strip().lower()
        if not last.startswith(b"end triggerblock"):
            return "it has no 'End TriggerBlock'"
    return None


def truncation(path: Path, frames: int) -> str | None:
    """A one-line description of how ``p`` is truncated after ``frames`` frames, or None."""
    suffix = path.suffix.lower()
    try:
        size = path.stat().st_size
    except OSError:
        return None
    if suffix == ".blf":
        want = _blf_announced_size(path)
        if want is not None and size < want:
            return (f"{path}: truncated BLF: the file has {size} of the {want} bytes its header "
                    f"announces; {frames} frames read")
    elif suffix in TEXT_SUFFIXES:
        why = _text_cut(path, suffix)
        if why is not None:
            return f"{path}: truncated {suffix} log ({why}); {frames} frames read, {size} bytes"
    elif suffix == ".mf4" and size:
        why = _mf4_cut(path, size)
        if why is not None:
            return f"{path}: truncated or damaged MF4 ({size} bytes: {why}); {frames} frames read"
    return None


def read_log(path: str) -> Iterator[Any]:
    """python-can messages of one log file, in file order; :class:`TruncatedInputError` after
    the last frame when the file ends inside a record or container."""
    require_cantools()
    import can

    file_path = Path(path)
    suffix = file_path.suffix.lower()
    if suffix not in READ_SUFFIXES and not file_path.is_dir():
        what = f"suffix {file_path.suffix!r}" if file_path.suffix else "no suffix"
        raise InputError(f"{path}: unknown CAN log format ({what}; one of "
                          f"{', '.join(READ_SUFFIXES)})")
    _check_format(file_path, suffix)
    if suffix == ".mf4":  # it begins as one (_check_format)
        # checked before asammdf opens it: asammdf prints a traceback when it fails to
        why = truncation(file_path, 0)
        if why is not None:
            raise TruncatedInputError(why, frames=0)
        logging.getLogger("asammdf").setLevel(logging.CRITICAL)  # its errors raise here
    try:
        reader = can.LogReader(str(file_path))
    except ImportError as exc:
        raise MissingExtra("export", f"{path}: this format needs {exc.name or exc}") from exc
    except Exception as exc:  # python-can raises many kinds on a foreign file
        raise InputError(f"{path}: not a readable {file_path.suffix} CAN log: {exc}") from exc
    frames = 0
    try:
        for msg in reader:
            frames += 1
            yield msg
    except EyeqError:
        raise
    except Exception as exc:  # cut or corrupt content
        why = truncation(file_path, frames)
        if why is not None:
            raise TruncatedInputError(why, frames=frames) from exc
        raise InputError(f"{path}: corrupt {file_path.suffix} CAN log after {frames} frames: "
                         f"{exc}") from exc
    finally:
        stop = getattr(reader, "stop", None)
        if callable(stop):
            stop()
    why = truncation(file_path, frames)
    if why is not None:
        raise TruncatedInputError(why, frames=frames)


def _mf4_cut(path: Path, size: int) -> str | None:
    """Why an MF4 cannot be whole, or None: every block reachable from the header block (at 64)
    must begin with a ``##XX`` identifier and lie inside the file, as must its links (MDF 4
    block layout: identifier, 4 reserved bytes, u64 length, u64 link count, the links)."""
    todo, seen = [64], set()
    with path.open("rb") as fh:
        while todo:
            at = todo.pop()
            if at in seen:
                continue
            seen.add(at)
            if at + 24 > size:
                return f"a block at byte {at} is beyond its end"
            fh.seek(at)
            head = fh.read(24)
            length, links = struct.unpack_from("<QQ", head, 8)
            if _MF4_BLOCK.match(head) is None or at + length > size or 24 + 8 * links > length:
                return f"the block at byte {at} is cut or damaged"
            todo.extend(link for link in struct.unpack(f"<{links}Q", fh.read(8 * links)) if link)
    return None


def open_bus(target: str) -> Any:
    """A python-can bus for ``INTERFACE:CHANNEL`` (``virtual:NAME``, ``socketcan:vcan0``...)."""
    require_cantools()
    import can

    interface, sep, channel = target.partition(":")
    if not interface or not sep or not channel:
        raise UsageError(f"--bus {target!r}: give INTERFACE:CHANNEL, e.g. virtual:camera or "
                         "socketcan:can0")
    return bus_of(can, target, interface, channel)


def bus_of(can: Any, target: str, interface: str, channel: str) -> Any:
    """python-can's bus on ``interface`` and ``channel``; :class:`AdapterError` if it fails."""
    try:
        return can.Bus(interface=interface, channel=channel, receive_own_messages=False)
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        raise AdapterError(f"cannot open CAN bus {target!r}: {exc}") from exc


def read_bus(bus: Any, *, duration: float | None = None, count: int | None = None,
             now: Callable[[], float] | None = None, poll: float = 0.2) -> Iterator[Any]:
    """python-can messages received on ``bus`` until ``count`` frames or ``duration`` seconds
    on the clock ``now`` (default: the monotonic clock) have passed; error frames are skipped.
    The caller shuts the bus down."""
    import time

    import can

    clock = now or time.monotonic
    end = None if duration is None else clock() + duration
    received = 0
    while count is None or received < count:
        timeout = poll if end is None else max(0.0, min(poll, end - clock()))
        try:
            msg = bus.recv(timeout)
        except (can.CanError, OSError, ValueError) as exc:
            raise AdapterError(f"CAN bus read failed after {received} frames: {exc}") from exc
        if msg is None:
            if end is not None and clock() >= end:
                return
            continue
        if msg.is_error_frame or msg.is_remote_frame:
            continue
        received += 1
        yield msg
