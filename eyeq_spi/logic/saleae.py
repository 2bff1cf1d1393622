"""Saleae SPI analyzer exports (``specs/bench.yaml`` ``saleae2``/``saleae1``), streamed.

- Logic 2 "Export table": ``name,type,start_time,duration,"mosi","miso"``; per analyzer
  (``name``) an ``enable`` row (CS falls), one ``result`` row per byte, a ``disable`` row (CS
  rises). Several analyzers (one per SPI channel) may share one file.
- Logic 1.x: ``Time [s],Packet ID,MOSI,MISO``; the rows of one ``Packet ID`` are one transfer.

A transfer is the bytes between CS falling and rising (§6), so a chip-select fault is a transfer
of the wrong length (L8). Bytes before a channel's first ``enable`` belong to a transfer the
capture cut: they are dropped, as is a transfer still open at the end. Transfer times are the
capture's (the ``enable`` row, or the first byte in Logic 1.x).

The csv module reads any shape of export; errors name their line.
"""

from __future__ import annotations

import csv
from collections.abc import Iterator
from datetime import UTC, datetime
from typing import Any

from eyeq_spi.capture.pcapng_io import Readable, Transfer
from eyeq_spi.errors import InputError
from eyeq_spi.logic.options import MAX_TRANSFER, Route, SpiOptions, bench_spec, whole_chunks

MAX_LINE = 1 << 16


class OpenTransfer:
    """A transfer between chip select falling and rising: its time and bytes per line."""

    __slots__ = ("lines", "time")

    def __init__(self, time: float | None) -> None:
        self.time = time
        self.lines: dict[str, bytearray] = {"mosi": bytearray(), "miso": bytearray()}


def seconds(text: str) -> float:
    """A capture time: seconds (Logic 1.x, Logic 2's default), or an ISO 8601 date and time
    (Logic 2's "Use ISO8601 timestamps" export option) as seconds since the epoch, UTC when
    no zone is given; ValueError for anything else."""
    try:
        return float(text)
    except ValueError:
        pass
    stamp_text = text.strip().strip('"')
    if len(stamp_text) < 10 or stamp_text[4:5] != "-":
        raise ValueError(text)
    stamp = datetime.fromisoformat(stamp_text)
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=UTC)
    return stamp.timestamp()


def _norm(cells: list[str]) -> list[str]:
    return [c.strip().strip('"').strip().lower() for c in cells]


def sniff(head: bytes) -> str | None:
    line = head.removeprefix(b"\xef\xbb\xbf").split(b"\n", 1)[0].decode("utf-8", "replace")
    cells = _norm(line.split(","))
    s2 = [h.lower() for h in bench_spec()["saleae2"]["header"]]
    s1 = [h.lower() for h in bench_spec()["saleae1"]["header"]]
    if cells[:len(s2)] == s2:
        return "saleae2"
    if cells[:2] == s1[:2]:
        return "saleae1"
    return None


_BYTES = {f"0x{v:02X}": v for v in range(256)} | {f"0x{v:02x}": v for v in range(256)}


def _byte(text: str, line: int) -> int | None:
    value = _BYTES.get(text)  # the usual hex radix, without parsing
    if value is not None:
        return value
    token = text.strip().strip('"')
    if not token:
        return None
    try:
        value = int(token, 0) if token[:2].lower() in ("0x", "0b") else int(token, 10)
    except ValueError:
        raise InputError(f"line {line}: {token[:20]!r} is not a byte (export with a hex, "
                         "decimal or binary radix)") from None
    if not 0 <= value <= 0xFF:
        raise InputError(f"line {line}: {value} is not a byte (set the analyzer to 8 bits)")
    return value


def _emit(tr: OpenTransfer, routes: list[Route]) -> Iterator[Transfer]:
    for route in routes:
        yield Transfer(tr.time, route.direction, bytes(tr.lines[route.line]))


def _time(text: str, where: str) -> float:
    try:
        return seconds(text)
    except ValueError:
        raise InputError(f"{where}: bad time {text[:30]!r}") from None


def read_saleae2(src: Readable, opts: SpiOptions, *, chunk_size: int = 1 << 20
                 ) -> Iterator[Transfer]:
    return _csv_errors(_saleae2(src, opts, chunk_size))


def read_saleae1(src: Readable, opts: SpiOptions, *, chunk_size: int = 1 << 20
                 ) -> Iterator[Transfer]:
    return _csv_errors(_saleae1(src, opts, chunk_size))


def _csv_errors(transfers: Iterator[Transfer]) -> Iterator[Transfer]:
    try:
        yield from transfers
    except csv.Error as exc:
        raise InputError(f"not a CSV export: {exc}") from None


def _csv_rows(src: Readable, chunk_size: int) -> tuple[list[str], Any]:
    """The normalised header cells (the UTF-8 BOM dropped) and a csv reader of the lines after
    it, read in chunks of whole lines (bounded memory: a line longer than 64 KiB is an error);
    the reader's ``line_num`` + 1 is the number of the line it read last."""
    chunks = whole_chunks(src, chunk_size, b"\n", MAX_LINE,
                          "line longer than 64 KiB: not a Saleae export")
    lines = (line for chunk in chunks for line in _lines(chunk))
    first = next(lines, "").removeprefix("\ufeff")
    return _norm(next(csv.reader([first]), [])), csv.reader(lines)


def _lines(chunk: bytes) -> list[str]:
    parts = chunk.split(b"\n")
    if not parts[-1]:
        parts.pop()
    return [p.rstrip(b"\r").decode("utf-8", "replace") for p in parts]


def _saleae2(src: Readable, opts: SpiOptions, chunk_size: int) -> Iterator[Transfer]:
    header, rows = _csv_rows(src, chunk_size)
    try:
        i_name, i_type, i_time = (header.index(c) for c in ("name", "type", "start_time"))
        cols = [(line, header.index(line)) for line in bench_spec()["saleae2"]["data_columns"]]
    except ValueError:
        raise InputError("not a Saleae Logic 2 SPI export: the header needs name, type, "
                         "start_time, mosi and miso") from None
    kinds = bench_spec()["saleae2"]["row_types"]
    k_start, k_byte, k_end = kinds["start"], kinds["byte"], kinds["end"]
    need = max(i_name, i_type, i_time, *(col for _, col in cols))
    open_: dict[str, OpenTransfer | None] = {}
    routes: dict[str, list[Route]] = {}
    results = enables = 0
    for row in rows:
        if not row:
            continue
        line_no = rows.line_num + 1
        if len(row) <= need:
            raise InputError(f"line {line_no}: {len(row)} columns, expected {len(header)}")
        name, kind = row[i_name], row[i_type]
        if name not in routes:
            routes[name] = opts.routes(name, len(routes) + 1)
        if kind != k_byte and kind != k_start:
            kind = kind.strip().lower()
        if kind == k_byte:
            results += 1
            tr = open_.get(name)
            if tr is None:
                continue  # a transfer cut by the start of the capture
            for line, col in cols:
                value = _byte(row[col], line_no)
                if value is not None:
                    buf = tr.lines[line]
                    buf.append(value)
                    if len(buf) > MAX_TRANSFER:
                        raise InputError(f"line {line_no}: transfer longer than {MAX_TRANSFER} "
                                         "bytes")
        elif kind == k_start:
            enables += 1
            open_[name] = OpenTransfer(_time(row[i_time], f"line {line_no}"))
        elif kind == k_end:
            tr = open_.pop(name, None)
            if tr is not None:
                yield from _emit(tr, routes[name])
        else:
            raise InputError(f"line {line_no}: row type {kind!r} is not enable/result/disable")
    if results and not enables:
        raise InputError("the SPI analyzer had no Enable (chip select) channel: transfers "
                         "cannot be framed")


def _saleae1(src: Readable, opts: SpiOptions, chunk_size: int) -> Iterator[Transfer]:
    header, rows = _csv_rows(src, chunk_size)
    want = [h.lower() for h in bench_spec()["saleae1"]["header"]]
    try:
        i_time, i_id, i_mosi, i_miso = (header.index(c) for c in want)
    except ValueError:
        raise InputError("not a Saleae Logic 1.x SPI export: the header needs "
                         + ", ".join(want)) from None
    routes = opts.routes("", 1)
    need = max(i_time, i_id, i_mosi, i_miso)
    tr: OpenTransfer | None = None
    packet: str | None = None
    for row in rows:
        if not row:
            continue
        line_no = rows.line_num + 1
        if len(row) <= need:
            raise InputError(f"line {line_no}: {len(row)} columns, expected {len(header)}")
        pid = row[i_id].strip()
        if not pid:
            raise InputError(f"line {line_no}: no Packet ID: the SPI analyzer had no Enable "
                             "(chip select) channel, transfers cannot be framed")
        if pid != packet:
            if tr is not None:
                yield from _emit(tr, routes)
            tr, packet = OpenTransfer(_time(row[i_time], f"line {line_no}")), pid
        assert tr is not None  # opened at this packet's first row
        for line, col in (("mosi", i_mosi), ("miso", i_miso)):
            value = _byte(row[col], line_no)
            if value is not None:
                tr.lines[line].append(value)
        if len(tr.lines["mosi"]) > MAX_TRANSFER or len(tr.lines["miso"]) > MAX_TRANSFER:
            raise InputError(f"line {line_no}: transfer longer than {MAX_TRANSFER} bytes")
    if tr is not None:
        # Logic 1.x marks no CS rising edge: the last packet ends with the file
        yield from _emit(tr, routes)
