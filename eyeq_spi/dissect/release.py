"""Which SW release a capture speaks, and captures opened with it (every capture reader's entry).

The release decides the DASP layouts (seed 004 §7.1.4), so it is chosen in this order:

1. ``--sw`` (the caller's ``sw``) when given;
2. the release the capture records (``eyeq-spi sw=<release>`` on its Section Header Block);
3. the release the EyeQ reports in its first ``release_sniff_transfers`` transfers: the
   GetEyeQVersions reply (§7.1.1.1.5), the boot status (§7.1.5.3) or
   EYEQ_BASE_DIAG_STATUS_MSG (§7.1.4.1); an unlisted release maps to the newest before it (D4);
4. the release whose DASP layouts fit the payload lengths seen there (the newest such);
5. else the newest release.

When ``--sw`` disagrees with 2 to 4, :attr:`Release.warning` is the one line naming both.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from functools import cache
from typing import IO, Any

from eyeq_spi.capture.pcapng_io import (
    Tail,
    Transfer,
    recorded_clock,
    recorded_release,
    release_sniff_transfers,
)
from eyeq_spi.catalog.messages import Catalog, SwKey, catalog, sw_release_text
from eyeq_spi.catalog.schema import sw_key
from eyeq_spi.codec.message import BOOT_ID, DASP_PROTOCOL, MessageCodec, classify
from eyeq_spi.dissect.engine import Dissector
from eyeq_spi.errors import EyeqError
from eyeq_spi.io.plain import PeekStream, open_transfers
from eyeq_spi.logic.options import SpiOptions

RECORDED = "recorded in the capture"
BASE_DIAG_ID = 0xA0  # EYEQ_BASE_DIAG_STATUS_MSG; its release bytes are at the same offsets in
# every layout (§7.1.4.1: timestamp_ms u32, apiVersion u8 u8, eyeqSwVersion u8 u8)


@dataclass(frozen=True)
class Release:
    """The release a capture is read with, where it came from, and the disagreement line."""

    key: SwKey
    source: str  # "--sw", RECORDED, "GetEyeQVersions reply", ..., "default"
    warning: str | None = None
    clock: str | None = None  # what the capture's timestamps were read from, None: not said

    @property
    def text(self) -> str:
        return sw_release_text(self.key)

    def as_dict(self) -> dict[str, Any]:
        return {"sw": self.text, "sw_source": self.source, "clock": self.clock}


def _known(cat: Catalog, major: int, minor: int) -> SwKey | None:
    """The ``specs/`` release for a reported one: the same, else the newest before it (D4)."""
    best = None
    for key in cat.sw_versions:
        if sw_key(key) <= (major, minor) and (best is None or sw_key(key) > sw_key(best)):
            best = key
    return best


def _reported(cat: Catalog, codec: MessageCodec, data: bytes) -> tuple[SwKey, str] | None:
    kind = classify(data)
    if kind == "MESP":
        out = codec.mesp.decode(data)
        fields = out.fields
        if out.name == "GetEyeQVersions" and out.header.get("reply") and not out.errors \
                and "eyeqSwVersionMajor" in fields:
            key = _known(cat, int(fields["eyeqSwVersionMajor"]), int(fields["eyeqSwVersionMinor"]))
            return (key, "GetEyeQVersions reply") if key else None
    elif kind == "BOOT" and data[:1] == bytes([BOOT_ID]):
        out = codec.decode(data)
        version = out.fields.get("ApplicationVersion") if not out.errors else None
        if version:
            key = _known(cat, int(version[0]), int(version[1]))
            return (key, "boot status") if key else None
    elif kind == "DASP" and len(data) >= 12 and data[1] == BASE_DIAG_ID:
        key = _known(cat, data[10], data[11])  # 4-byte header, then the payload's bytes 6, 7
        return (key, "EYEQ_BASE_DIAG_STATUS_MSG") if key else None
    return None


def _fitting(cat: Catalog, lengths: set[tuple[int, int]]) -> list[SwKey]:
    """The releases whose DASP layouts fit the most of the (data ID, length) pairs seen."""
    score: dict[SwKey, int] = {}
    for key in cat.sw_versions:
        codec = MessageCodec(key, cat)
        fitting = 0
        for data_id, length in lengths:
            msg = codec.dasp_message(data_id)
            if msg is None:
                continue
            try:
                if codec.layout(msg).size == length - 4:
                    fitting += 1
            except EyeqError:  # a layout this release cannot build does not fit
                continue
        score[key] = fitting
    best = max(score.values(), default=0)
    return [k for k in cat.sw_versions if best and score[k] == best]


def infer_release(transfers: Iterable[Transfer], cat: Catalog | None = None
                  ) -> tuple[SwKey, str] | None:
    """The release the traffic shows (steps 3 and 4 of the module docstring), with where it was
    seen, or None when nothing in ``transfers`` tells."""
    cat = cat or catalog()
    codec = MessageCodec(cat=cat)
    messages: list[bytes] = []
    sniff = Dissector(codec=codec, on_message=messages.append)
    lengths: set[tuple[int, int]] = set()
    for transfer in transfers:
        for _ in sniff.feed(transfer):
            pass
        for data in messages:
            found = _reported(cat, codec, data)
            if found is not None:
                return found
            if len(data) >= 4 and data[0] == DASP_PROTOCOL:
                lengths.add((data[1], len(data)))
        messages.clear()
    fit = _fitting(cat, lengths)
    if not fit:
        return None
    newest = max(fit, key=sw_key)
    names = ", ".join(sw_release_text(k) for k in fit)
    return newest, f"DASP payload lengths (fit {names})"


def choose_release(sw: str | None, found: tuple[SwKey, str] | None, name: str,
                   cat: Catalog | None = None) -> Release:
    """Step 1 against what the capture says; the warning when they disagree."""
    cat = cat or catalog()
    fkey, fsrc = found if found is not None else (None, None)
    if sw is None:
        if fkey is None:
            return Release(cat.default_sw, "default")
        return Release(fkey, fsrc or RECORDED)
    key = cat.sw(sw)
    warning = None
    if fkey is not None and fkey != key:
        warning = (f"{name}: read as SW {sw_release_text(key)} (--sw) but the capture says "
                   f"SW {sw_release_text(fkey)} ({fsrc})")
    return Release(key, "--sw", warning)


@cache
def codec_for(key: str) -> MessageCodec:
    """One codec per release for the whole process (building one reads ``specs/``)."""
    return MessageCodec(key)


@dataclass
class Capture:
    """An opened capture: its format, its transfers, the release to read them with, and what
    was left unread at its end (filled once ``transfers`` is exhausted)."""

    kind: str
    transfers: Iterator[Transfer]
    release: Release
    tail: Tail = field(default_factory=Tail)
    # the fast path's chunks of transfers (:mod:`eyeq_spi.capture.pcapng_fast`), which
    # ``transfers`` are read from: a caller reads one or the other; None for the reference readers
    chunks: Iterator[Any] | None = None


def open_capture(stream: IO[bytes], fmt: str | None = None, direction: str | None = None,
                 spi: SpiOptions | None = None, *, sw: str | None = None, name: str = "-"
                 ) -> Capture:
    """:func:`~eyeq_spi.io.plain.open_transfers` with the release resolved (module docstring)
    and a file that ends inside a pcapng block read up to its last whole block (:class:`Tail`)."""
    tail = Tail()
    peek = stream if isinstance(stream, PeekStream) else PeekStream(stream)
    head = peek.head  # before the reader takes it
    kind, transfers = open_transfers(peek, fmt, direction, spi, tail)  # type: ignore[arg-type]
    release, transfers = with_release(transfers, head, sw, name)
    return Capture(kind, transfers, release, tail)


def with_release(items: Iterator[Any], head: bytes, sw: str | None, name: str,
                 transfers: Callable[[Any], list[Transfer]] = lambda item: [item]
                 ) -> tuple[Release, Iterator[Any]]:
    """The release of the capture that starts with ``head`` (module docstring), and its
    ``items`` (transfers, or what ``transfers`` turns into them) with the ones looked at to
    infer the release first."""
    recorded = recorded_release(head)
    if recorded is not None:
        release = choose_release(sw, (recorded, RECORDED), name)
    else:
        looked: list[Any] = []
        seen: list[Transfer] = []
        fault: EyeqError | None = None
        try:
            while len(seen) < release_sniff_transfers():
                item = next(items, None)
                if item is None:
                    break
                looked.append(item)
                seen += transfers(item)
        except EyeqError as exc:  # raised after the items before it, as the reader would
            fault = exc
        release = choose_release(sw, infer_release(seen[: release_sniff_transfers()]), name)
        items = then(looked, fault, items)
    return replace(release, clock=recorded_clock(head)), items


def then(head: list[Any], fault: EyeqError | None, rest: Iterator[Any]) -> Iterator[Any]:
    yield from head
    if fault is not None:
        raise fault
    yield from rest
