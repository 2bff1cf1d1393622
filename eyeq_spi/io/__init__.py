"""One registry of the file formats eyeq-spi reads and writes (python-can's ``can.io`` pattern).

Each :class:`Format` names its kind, suffixes, the ``module:callable`` that implements it
(imported on first use by :func:`load`, so the command line starts fast with every format
known) and the optional extra it needs (:class:`~eyeq_spi.errors.MissingExtra` names the
``pip install 'eyeq-spi[EXTRA]'``). Readers are found by name (``--format``) or by content
(:func:`eyeq_spi.io.plain.detect`, every sniffer in registry order: suffixes never decide) and
open through :func:`eyeq_spi.io.plain.open_transfers`; writers by name. CAN logs are read by
python-can's own registry. The table in ``docs/captures.md`` is :func:`markdown_table`.
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable, Iterator
from pathlib import PurePath
from typing import Any, Literal, NamedTuple

from eyeq_spi.errors import MissingExtra, UnknownFormatError

Kind = Literal["capture reader", "capture writer", "record writer", "can log"]
CAPTURE_READER: Kind = "capture reader"  # a file of SPI transfers -> Transfer(time, dir, data)
CAPTURE_WRITER: Kind = "capture writer"  # Transfers -> a file of SPI transfers
RECORD_WRITER: Kind = "record writer"  # the dissector's records (docs/dissector.md) -> a file
CAN_LOG: Kind = "can log"  # a CAN log python-can reads (its own registry, by suffix)
KINDS: tuple[Kind, ...] = (CAPTURE_READER, CAPTURE_WRITER, RECORD_WRITER, CAN_LOG)

Takes = Literal["direction", "spi", "tail", ""]
Truncation = Literal["error", "drop", "short", ""]


class Format(NamedTuple):  # a NamedTuple: dataclasses would cost the CLI's start-up 10 ms
    """A registered format. Capture readers are called ``target(stream, arg)``, ``arg`` the
    one ``takes`` names (the ``direction`` of a one-channel input, the ``spi`` options of a
    logic-analyzer export, the ``tail`` of a pcapng cut inside a block); capture writers
    ``target(transfers, path, **options) -> transfers written``; record writers are the
    dissector's writer classes. ``sniff``: ``module:function(head) -> name | None``; ``text``:
    skipped for a head no text begins with; ``resolution``: seconds to which times survive a
    round trip (0: exactly, None: no times); ``channels``: directions in one file;
    ``truncation``: what a cut file gives (``error``, ``drop`` the cut transfer, ``short``: the
    last transfer as far as it goes); ``fast``: the fast path's chunk reader, if any."""

    name: str
    kind: Kind
    suffixes: tuple[str, ...]
    target: str
    summary: str
    extra: str | None = None  # pip extra: pip install 'eyeq-spi[EXTRA]'
    needs: tuple[str, ...] = ()  # top-level modules that extra brings
    sniff: str | None = None
    text: bool = False
    takes: Takes = ""
    resolution: float | None = None
    channels: int = 2
    truncation: Truncation = ""
    fast: str | None = None  # readers: the fast (numpy) path's chunk reader, if it has one

    @property
    def module(self) -> str:
        return self.target.split(":", 1)[0]

    @property
    def callable_name(self) -> str:
        return self.target.split(":", 1)[1]


_PLAIN = "eyeq_spi.io.plain"
_WRITERS = "eyeq_spi.io.writers"

# Order matters for detection: the first sniffer that names a format wins (pcapng's magic,
# then the text formats, then raw transfers with a valid CRC).
REGISTRY: tuple[Format, ...] = (
    Format("pcapng", CAPTURE_READER, (".pcapng",), f"{_PLAIN}:read_pcapng_input",
           "our captures: one interface per SPI channel (specs/capture.yaml)",
           sniff=f"{_PLAIN}:sniff_pcapng", takes="tail", resolution=1e-6, truncation="error",
           fast="eyeq_spi.capture.pcapng_fast:pcapng_chunks"),
    Format("saleae2", CAPTURE_READER, (".csv",), "eyeq_spi.logic.saleae:read_saleae2",
           "Saleae Logic 2 SPI analyzer export table (one analyzer per channel)",
           sniff="eyeq_spi.logic.saleae:sniff", text=True, takes="spi", resolution=0.0,
           truncation="drop"),
    Format("saleae1", CAPTURE_READER, (".csv",), "eyeq_spi.logic.saleae:read_saleae1",
           "Saleae Logic 1.x SPI analyzer export (Packet ID per transfer)",
           sniff="eyeq_spi.logic.saleae:sniff", text=True, takes="spi", resolution=0.0,
           channels=1, truncation="short"),
    Format("vcd", CAPTURE_READER, (".vcd",), "eyeq_spi.logic.vcd:read_vcd",
           "VCD waveforms of CS, CLK, MOSI, MISO (sigrok, PulseView, simulators)",
           sniff="eyeq_spi.logic.vcd:sniff", text=True, takes="spi", resolution=1e-8,
           truncation="drop"),
    Format("hex", CAPTURE_READER, (".hex", ".txt"), f"{_PLAIN}:read_hex",
           "one transfer per line: [TIME] [h2e or e2h] HEX BYTES (# comments)",
           sniff=f"{_PLAIN}:sniff_hex", text=True, takes="direction", resolution=0.0,
           truncation="short"),
    Format("raw", CAPTURE_READER, (".raw", ".bin"), f"{_PLAIN}:read_raw",
           "concatenated 128-byte transfers of one channel, no times",
           sniff=f"{_PLAIN}:sniff_raw", takes="direction", channels=1, truncation="error"),
    Format("pcapng", CAPTURE_WRITER, (".pcapng",), f"{_WRITERS}:write_pcapng",
           "what demo, host and sim --capture write (crash-safe, streamed)"),
    Format("vcd", CAPTURE_WRITER, (".vcd",), f"{_WRITERS}:write_vcd_file",
           "SPI waveforms for PulseView and sigrok (export --vcd)"),
    Format("sr", CAPTURE_WRITER, (".sr",), "eyeq_spi.logic.sr_write:write_sr_file",
           "SPI waveforms as a sigrok session file, compressed (export --sr; PulseView)"),
    Format("hex", CAPTURE_WRITER, (".hex", ".txt"), f"{_PLAIN}:write_hex",
           "one transfer per line: TIME DIRECTION HEX"),
    Format("raw", CAPTURE_WRITER, (".raw", ".bin"), f"{_PLAIN}:write_raw",
           "the transfers of one channel, concatenated"),
    Format("jsonl", RECORD_WRITER, (".jsonl", ".ndjson"), "eyeq_spi.io.jsonl:JsonLinesWriter",
           "JSON Lines: every record (dissect --json)"),
    Format("csv", RECORD_WRITER, (".csv",), "eyeq_spi.dissect.output:TableWriter",
           "a directory of tables, one CSV file per message type (dissect --csv)"),
    Format("parquet", RECORD_WRITER, (".parquet",), "eyeq_spi.dissect.output:TableWriter",
           "a directory of tables, one Parquet file per message type (dissect --parquet)",
           extra="parquet", needs=("pyarrow",)),
    Format("mdf4", RECORD_WRITER, (".mf4", ".mdf"), "eyeq_spi.interop.mdf:MdfWriter",
           "decoded signals for asammdf and CANape (export --mdf)",
           extra="export", needs=("asammdf",)),
    Format("mcap", RECORD_WRITER, (".mcap",), "eyeq_spi.interop.mcap_out:McapWriter",
           "raw transfers and decoded messages for Foxglove (export --mcap)",
           extra="export", needs=("mcap", "zstandard")),
    Format("can-log", CAN_LOG, (".blf", ".asc", ".log", ".trc", ".mf4", ".csv"),
           "eyeq_spi.can.logs:read_log",
           "CAN logs: python-can's own registry reads them by suffix (eyeq-spi can)",
           extra="can", needs=("can", "cantools")),
)


def names(kind: Kind) -> tuple[str, ...]:
    """The names of one kind, in registry order (``choices=`` of ``--format``)."""
    return tuple(f.name for f in REGISTRY if f.kind == kind)


def readers() -> tuple[str, ...]:
    """The capture readers' names (``--format``)."""
    return names(CAPTURE_READER)


def formats(kind: Kind) -> tuple[Format, ...]:
    return tuple(f for f in REGISTRY if f.kind == kind)


def get(name: str, kind: Kind = CAPTURE_READER) -> Format:
    """The format ``name`` of ``kind``; an unknown name lists the known ones."""
    for entry in REGISTRY:
        if entry.kind == kind and entry.name == name:
            return entry
    raise UnknownFormatError(f"unknown {kind} format {name!r} (one of "
                             f"{', '.join(names(kind))})")


def can_log_hint(path: str | PurePath) -> str | None:
    """For a file a capture reader refused: the command that reads it when its suffix is a CAN
    log's and no capture reader's (``drive.blf``), else None."""
    suffix = PurePath(path).suffix.lower()
    if not suffix or any(suffix in f.suffixes for f in formats(CAPTURE_READER)):
        return None
    if any(suffix in f.suffixes for f in formats(CAN_LOG)):
        return f"a CAN log ({suffix}) is read by: eyeq-spi can decode {path}"
    return None


def missing(fmt: Format) -> str | None:
    """The first module of ``fmt``'s extra that is not installed (None: all are), found
    without importing anything."""
    for mod in fmt.needs:
        try:
            if importlib.util.find_spec(mod) is None:
                return mod
        except (ImportError, ValueError):
            return mod
    return None


def load(fmt: Format | str, kind: Kind = CAPTURE_READER, *,
         what: str | None = None) -> Callable[..., Any]:
    """``fmt``'s callable, imported now (:class:`MissingExtra` when its extra is not
    installed; ``what``: how the user asked for it, for the message)."""
    entry = get(fmt, kind) if isinstance(fmt, str) else fmt
    mod = missing(entry)
    if mod is not None and entry.extra is not None:
        raise MissingExtra(entry.extra, f"{what or entry.name} needs {mod}")
    try:
        module = importlib.import_module(entry.module)
    except ImportError as exc:
        if entry.extra is not None and (exc.name or "").split(".")[0] in entry.needs:
            raise MissingExtra(entry.extra, f"{what or entry.name} needs {exc.name}") from None
        raise
    obj: Callable[..., Any] = getattr(module, entry.callable_name)
    return obj


def sniffers(text: bool) -> Iterator[tuple[str, Callable[[bytes], str | None]]]:
    """The capture readers' sniffers, once each, in registry order, each module imported when
    the caller gets that far (a pcapng file, sniffed first, imports no logic-analyzer reader);
    ``text=False`` leaves out the text formats'."""
    seen: set[str] = set()
    for entry in formats(CAPTURE_READER):
        if entry.sniff is None or entry.sniff in seen or (entry.text and not text):
            continue
        seen.add(entry.sniff)
        mod, _, fn = entry.sniff.partition(":")
        yield entry.sniff, getattr(importlib.import_module(mod), fn)


_CUT = {"error": "error", "drop": "cut transfer dropped", "short": "last transfer as cut"}


def markdown_table() -> str:
    """The table of formats in ``docs/captures.md``."""
    rows = ["| Format | Kind | Suffixes | Needs | Channels | Times | A cut file | What |",
            "|---|---|---|---|---|---|---|---|"]
    for entry in REGISTRY:
        extra = f"`eyeq-spi[{entry.extra}]`" if entry.extra else "-"
        suffixes = " ".join(f"`{s}`" for s in entry.suffixes) or "python-can's"
        times = channels = cut = "-"
        if entry.kind == CAPTURE_READER:
            channels = "both" if entry.channels == 2 else "one"
            cut = _CUT[entry.truncation]
            if entry.resolution is None:
                times = "none"
            elif entry.resolution == 0:
                times = "as written"
            elif entry.resolution >= 1e-6:
                times = f"{entry.resolution * 1e6:g} µs"
            else:
                times = f"{entry.resolution * 1e9:g} ns"
        rows.append(f"| `{entry.name}` | {entry.kind} | {suffixes} | {extra} | {channels} | "
                    f"{times} | {cut} | {entry.summary} |")
    return "\n".join(rows) + "\n"

