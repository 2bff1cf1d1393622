"""Saleae SPI analyzer exports (``specs/bench.yaml`` ``saleae2``/``saleae1``), streamed.

- Logic 2 "Export table": ``name,type,start_time,duration,"mosi","miso"``; per analyzer
  (``name``) an ``enable`` row (CS falls), one ``result`` row per byte, a ``disable`` row (CS
  rises). Several analyzers (one per SPI channel) may share one file.
- Logic 1.x: ``Time [s],Packet ID,MOSI,MISO``; the rows of one ``Packet ID`` are one transfer.

A transfer is the bytes between CS falling and rising (§6), so a chip-select fault is a transfer
of the wrong length (L8). Bytes before a channel's first ``enable`` belong to a transfer the
capture cut: they are dropped, as is a transfer still open at the end. Record times are the
capture's (the ``enable`` row, or the first byte in Logic 1.x).
"""

from __future__ import annotations

import csv
from collections.abc import Iterator
from typing import Protocol

from eyeq_spi.capture.pcapng_io import Record
from eyeq_spi.logic.options import MAX_TRANSFER, LogicInputError, Route, SpiOptions, bench_spec

MAX_LINE = 1 << 16


class ByteSource(Protocol):
    def read(self, n: int = -1) -> bytes: ...


def text_lines(src: ByteSource, chunk: int = 1 << 16) -> Iterator[str]:
    """Decoded lines of a byte stream (UTF-8, BOM dropped), bounded memory."""
    buf = b""
    first = True
    while True:
        data = src.read(chunk)
        buf += data
        parts = buf.split(b"\n")
        buf = parts.pop() if data else b""
        for raw in parts:
            if first:
                raw = raw.removeprefix(b"\xef\xbb\xbf")
                first = False
            yield raw.rstrip(b"\r").decode("utf-8", "replace")
        if not data:
            if buf:
                yield buf.decode("utf-8", "replace")
            return
        if len(buf) > MAX_LINE:
            raise LogicInputError("line longer than 64 KiB: not a Saleae export")


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


def _byte(text: str, n: int) -> int | None:
    v = _BYTES.get(text)  # the usual hex radix, without parsing
    if v is not None:
        return v
    t = text.strip().strip('"')
    if not t:
        return None
    try:
        v = int(t, 0) if t[:2].lower() in ("0x", "0b") else int(t, 10)
    except ValueError:
        raise LogicInputError(f"line {n}: {t[:20]!r} is not a byte (export with a hex, "
                              "decimal or binary radix)") from None
    if not 0 <= v <= 0xFF:
        raise LogicInputError(f"line {n}: {v} is not a byte (set the analyzer to 8 bits)")
    return v


class _Open:
    __slots__ = ("lines", "time")

    def __init__(self, time: float | None) -> None:
        self.time = time
        self.lines: dict[str, bytearray] = {"mosi": bytearray(), "miso": bytearray()}


def _emit(tr: _Open, routes: list[Route]) -> Iterator[Record]:
    for r in routes:
        yield Record(tr.time, r.direction, bytes(tr.lines[r.line]))


def _time(text: str, where: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise LogicInputError(f"{where}: bad time {text[:30]!r}") from None


def read_saleae2(src: ByteSource, opts: SpiOptions) -> Iterator[Record]:
    try:
        yield from _saleae2(src, opts)
    except csv.Error as exc:
        raise LogicInputError(f"not a CSV export: {exc}") from None


def read_saleae1(src: ByteSource, opts: SpiOptions) -> Iterator[Record]:
    try:
        yield from _saleae1(src, opts)
    except csv.Error as exc:
        raise LogicInputError(f"not a CSV export: {exc}") from None


def _saleae2(src: ByteSource, opts: SpiOptions) -> Iterator[Record]:
    lines = text_lines(src)
    header = _norm(next(csv.reader([next(lines, "")]), []))
    try:
        i_name, i_type, i_time = (header.index(c) for c in ("name", "type", "start_time"))
        cols = {line: header.index(line) for line in bench_spec()["saleae2"]["data_columns"]}
    except ValueError:
        raise LogicInputError("not a Saleae Logic 2 SPI export: the header needs name, type, "
                              "start_time, mosi and miso") from None
    kinds = bench_spec()["saleae2"]["row_types"]
    k_start, k_byte = kinds["start"], kinds["byte"]
    open_: dict[str, _Open | None] = {}
    routes: dict[str, list[Route]] = {}
    results = enables = 0
    need = max(i_name, i_type, i_time, *cols.values())
    col_list = list(cols.items())
    for n, row in enumerate(csv.reader(lines), start=2):
        if not row:
            continue
        if len(row) <= need:
            raise LogicInputError(f"line {n}: {len(row)} columns, expected {len(header)}")
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
            for line, col in col_list:
                v = _byte(row[col], n)
                if v is not None:
                    buf = tr.lines[line]
                    buf.append(v)
                    if len(buf) > MAX_TRANSFER:
                        raise LogicInputError(f"line {n}: transfer longer than {MAX_TRANSFER} "
                                              "bytes")
        elif kind == k_start:
            enables += 1
            open_[name] = _Open(_time(row[i_time], f"line {n}"))
        elif kind == kinds["end"]:
            tr = open_.pop(name, None)
            if tr is not None:
                yield from _emit(tr, routes[name])
        else:
            raise LogicInputError(f"line {n}: row type {kind!r} is not enable/result/disable")
    if results and not enables:
        raise LogicInputError("the SPI analyzer had no Enable (chip select) channel: transfers "
                              "cannot be framed")


def _saleae1(src: ByteSource, opts: SpiOptions) -> Iterator[Record]:
    lines = text_lines(src)
    header = _norm(next(csv.reader([next(lines, "")]), []))
    want = [h.lower() for h in bench_spec()["saleae1"]["header"]]
    try:
        i_time, i_id, i_mosi, i_miso = (header.index(c) for c in want)
    except ValueError:
        raise LogicInputError("not a Saleae Logic 1.x SPI export: the header needs "
                              + ", ".join(want)) from None
    routes = opts.routes("", 1)
    tr: _Open | None = None
    packet: str | None = None
    for n, row in enumerate(csv.reader(lines), start=2):
        if not row:
            continue
        if len(row) <= max(i_time, i_id, i_mosi, i_miso):
            raise LogicInputError(f"line {n}: {len(row)} columns, expected {len(header)}")
        pid = row[i_id].strip()
        if not pid:
            raise LogicInputError(f"line {n}: no Packet ID: the SPI analyzer had no Enable "
                                  "(chip select) channel, transfers cannot be framed")
        if pid != packet:
            if tr is not None:
                yield from _emit(tr, routes)
            tr, packet = _Open(_time(row[i_time], f"line {n}")), pid
        assert tr is not None
        for line, col in (("mosi", i_mosi), ("miso", i_miso)):
            v = _byte(row[col], n)
            if v is not None:
                tr.lines[line].append(v)
        if len(tr.lines["mosi"]) > MAX_TRANSFER or len(tr.lines["miso"]) > MAX_TRANSFER:
            raise LogicInputError(f"line {n}: transfer longer than {MAX_TRANSFER} bytes")
    if tr is not None:
        # Logic 1.x marks no CS rising edge: the last packet ends with the file
        yield from _emit(tr, routes)
