"""The format registry (``eyeq_spi.io``): every capture reader reads back what was written in its
format, cut and empty files give typed errors, record writers round-trip, every entry imports,
and ``docs/captures.md`` shows the registry (python-can's ``ReaderWriterTest`` pattern: the tests
iterate the registry, so a new format is covered when it is registered)."""

from __future__ import annotations

import contextlib
import csv
import importlib
import io
import json
import math
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi import io as registry
from eyeq_spi.capture.pcapng_io import Transfer, read_pcapng
from eyeq_spi.errors import InputError, MissingExtra, TruncatedInputError, UnknownFormatError
from eyeq_spi.io import CAPTURE_READER, CAPTURE_WRITER, RECORD_WRITER, Format
from eyeq_spi.io.plain import open_transfers

pytestmark = pytest.mark.twin  # runs a reference/fast twin: also run with EYEQ_SPI_EXACT=1

ROOT = Path(__file__).resolve().parents[1]
READERS = registry.formats(CAPTURE_READER)
ONE_CHANNEL = "e2h"  # the direction a one-channel format is written and read with


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> list[Transfer]:
    """0.3 s of the emulator in virtual time (the bring-up: both channels, DATA and ACK frames;
    the run is judged not finished, exit 1)."""
    from eyeq_spi.cli import main

    path = tmp_path_factory.mktemp("io") / "demo.pcapng"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["demo", "--virtual-time", "--duration", "0.3", "--capture", str(path),
                     "--json"]) in (0, 1)
    with path.open("rb") as fh:
        recs = list(read_pcapng(fh))
    assert len(recs) > 20 and {r.direction for r in recs} == {"h2e", "e2h"}
    # one transfer every 250 us, in capture order: no transfer overlaps another (a VCD writer
    # moves one that would overlap its channel's previous transfer, as an ACK handed over with
    # a DATA frame; tests/test_logic.py covers that)
    return [Transfer(round(0.15 + i * 250e-6, 6), r.direction, r.data) for i, r in enumerate(recs)]


# Formats we read but do not write (a logic analyzer writes them): the test writes them.
def _saleae2(records: list[Transfer], path: Path) -> None:
    lines = ['name,type,start_time,duration,"mosi","miso"']
    for r in records:
        t = r.time or 0.0
        lines.append(f'"{r.direction}","enable",{t!r},2e-08,,')
        lines += [f'"{r.direction}","result",{t + 1e-6 + i * 8e-7!r},8e-07,0x{b:02X},0xFF'
                  for i, b in enumerate(r.data)]
        lines.append(f'"{r.direction}","disable",{t + 1.1e-4!r},2e-08,,')
    path.write_text("\n".join(lines) + "\n")


def _saleae1(records: list[Transfer], path: Path) -> None:
    lines = ["Time [s],Packet ID,MOSI,MISO"]
    for pid, r in enumerate(x for x in records if x.direction == ONE_CHANNEL):
        t = r.time or 0.0
        lines += [f"{t + i * 8e-7!r},{pid},0x{b:02X},0x00" for i, b in enumerate(r.data)]
    path.write_text("\n".join(lines) + "\n")


ENCODERS: dict[str, Callable[[list[Transfer], Path], None]] = {"saleae2": _saleae2,
                                                            "saleae1": _saleae1}


def _write(fmt: Format, records: list[Transfer], path: Path) -> None:
    writer = next((w for w in registry.formats(CAPTURE_WRITER) if w.name == fmt.name), None)
    if writer is not None:
        kw = {"direction": ONE_CHANNEL} if fmt.channels == 1 else {}
        registry.load(writer)(records, path, **kw)
    else:
        assert fmt.name in ENCODERS, f"{fmt.name}: register a capture writer or give the test " \
            "an encoder"
        ENCODERS[fmt.name](records, path)


def _expected(fmt: Format, records: list[Transfer]) -> list[Transfer]:
    if fmt.channels == 1:
        records = [r for r in records if r.direction == ONE_CHANNEL]
    return records


def _read(fmt: Format, data: bytes, name: str | None = None) -> tuple[str, list[Transfer]]:
    direction = ONE_CHANNEL if fmt.channels == 1 else None
    kind, it = open_transfers(io.BytesIO(data), name, direction)
    return kind, list(it)


@pytest.mark.parametrize("fmt", READERS, ids=lambda f: f.name)
def test_reader_reads_back_the_capture(fmt: Format, capture: list[Transfer],
                                       tmp_path: Path) -> None:
    """Found by content, the transfers (direction, bytes, time within the format's resolution)
    come back in order; by name too."""
    path = tmp_path / f"capture{fmt.suffixes[0]}"
    _write(fmt, capture, path)
    want = _expected(fmt, capture)
    data = path.read_bytes()
    for name in (None, fmt.name):
        kind, got = _read(fmt, data, name)
        assert kind == fmt.name
        assert [(r.direction, r.data) for r in got] == [(r.direction, r.data) for r in want]
        if fmt.resolution is None:
            assert all(r.time is None for r in got)
        else:
            tol = fmt.resolution or 1e-12
            bad = [(g.time, w.time) for g, w in zip(got, want, strict=True)
                   if g.time is None or w.time is None or abs(g.time - w.time) > tol]
            assert not bad, f"{len(bad)} times off by more than {fmt.resolution} s: {bad[:3]}"


# capture writers with no reader of their own, each read back by a test with its own decoder
WRITTEN_ELSEWHERE = {"sr": "tests/test_logic_sr_write.py::"
                           "test_session_file_holds_every_transfer_at_its_time"}


@pytest.mark.parametrize("fmt", registry.formats(CAPTURE_WRITER), ids=lambda f: f.name)
def test_capture_writer_reads_back(fmt: Format, capture: list[Transfer], tmp_path: Path) -> None:
    """Every capture writer's file gives back the transfers it was given: through the reader
    of the same name, or through the decoder of the test that reads that format."""
    if fmt.name in WRITTEN_ELSEWHERE:
        test = WRITTEN_ELSEWHERE[fmt.name]
        assert (ROOT / test.split("::")[0]).read_text().count(f"def {test.split('::')[1]}(")
        pytest.skip(f"read back by {test}")
    reader = registry.get(fmt.name, CAPTURE_READER)  # a writer without a reader: list it above
    path = tmp_path / f"capture{fmt.suffixes[0]}"
    _write(reader, capture, path)
    _, got = _read(reader, path.read_bytes(), reader.name)
    want = _expected(reader, capture)
    assert [(r.direction, r.data) for r in got] == [(r.direction, r.data) for r in want]


@pytest.mark.parametrize("fmt", READERS, ids=lambda f: f.name)
def test_a_cut_file_gives_its_documented_result(fmt: Format, capture: list[Transfer],
                                                tmp_path: Path) -> None:
    """Cut in the middle of a transfer: a typed truncation error (``error``); or the transfers
    before it (``drop``: a logic analyzer stopped mid-transfer); or the last transfer as far as
    it goes (``short``: a format that marks no transfer's end). A text file cut inside a row
    or line is an error naming that line. Never another exception."""
    path = tmp_path / f"capture{fmt.suffixes[0]}"
    _write(fmt, capture, path)
    data = path.read_bytes()
    mid = len(data) // 2
    mid -= 1 if mid % 128 == 0 else 0  # inside a raw transfer
    cuts = [mid, data.rindex(b"\n", 0, mid) + 1] if fmt.text else [mid]
    want = _expected(fmt, capture)
    for cut in cuts:
        if fmt.truncation == "error":
            with pytest.raises(TruncatedInputError, match=r"ends inside|truncated"):
                _read(fmt, data[:cut], fmt.name)
            continue
        try:
            _, got = _read(fmt, data[:cut], fmt.name)
        except InputError as exc:
            assert cut == mid and fmt.text and re.search(r"line \d+", str(exc)), exc
            continue
        assert 0 < len(got) < len(want)
        assert [(r.direction, r.data) for r in got[:-1]] == \
            [(r.direction, r.data) for r in want[:len(got) - 1]]
        last, orig = got[-1], want[len(got) - 1]
        assert last.direction == orig.direction
        if fmt.truncation == "drop":
            assert last.data == orig.data
        else:
            assert fmt.truncation == "short" and orig.data.startswith(last.data)


RANDOM = bytes((i * 7919 + (i >> 3) * 104729 + 0x5A) & 0xFF for i in range(3000))
"""Bytes that never were a capture (a fixed pattern: no two runs differ)."""


@pytest.mark.parametrize("fmt", READERS, ids=lambda f: f.name)
def test_a_file_that_never_was_the_format_is_not_it(fmt: Format, tmp_path: Path) -> None:
    """Read as this format (``--format``): "not a ..." (an input error, exit 2), never
    "truncated", which only a file that began as its format is; detected: not a capture.
    Through the command line too, named with the format's suffix."""
    from eyeq_spi.cli import main

    for head in (RANDOM, RANDOM[:100]):
        with pytest.raises(InputError) as exc:
            _read(fmt, head, fmt.name)
        assert not isinstance(exc.value, TruncatedInputError), exc.value
        assert "not a" in str(exc.value) and "\n" not in str(exc.value), exc.value
        assert str(exc.value).isprintable(), exc.value  # no binary bytes echoed
    with pytest.raises(InputError, match="not an EyeQ SPI capture"):
        _read(fmt, RANDOM)
    path = tmp_path / f"random{fmt.suffixes[0]}"
    path.write_bytes(RANDOM)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        assert main(["dissect", str(path)]) == 2
        assert main(["dissect", "--format", fmt.name, str(path)]) == 2
    assert "truncated" not in err.getvalue() and "not a" in err.getvalue()


def test_a_can_log_given_to_dissect_names_can_decode(tmp_path: Path) -> None:
    from eyeq_spi.cli import main

    path = tmp_path / "drive.blf"
    path.write_bytes(b"LOGG" + RANDOM)
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(["dissect", str(path)]) == 2
    assert f"eyeq-spi can decode {path}" in err.getvalue()
    assert len(err.getvalue().strip().splitlines()) == 1


@pytest.mark.parametrize("fmt", READERS, ids=lambda f: f.name)
def test_an_empty_file_is_a_clear_error(fmt: Format) -> None:
    with pytest.raises(InputError, match="empty input"):
        _read(fmt, b"")
    with pytest.raises(InputError) as exc:
        _read(fmt, b"", fmt.name)
    assert str(exc.value) and "\n" not in str(exc.value)


def test_unknown_names_list_the_known_ones(tmp_path: Path) -> None:
    with pytest.raises(UnknownFormatError) as exc:
        open_transfers(io.BytesIO(b"x" * 200), "pcap")
    assert all(n in str(exc.value) for n in registry.readers())
    with pytest.raises(InputError, match="formats: " + ", ".join(registry.readers())):
        open_transfers(io.BytesIO(bytes(range(14, 28)) * 20))
    from eyeq_spi.dissect.output import TableWriter

    with pytest.raises(UnknownFormatError, match="one of csv, parquet"):
        TableWriter(str(tmp_path), "xlsx")
    assert registry.get("jsonl", RECORD_WRITER).suffixes == (".jsonl", ".ndjson")


@pytest.mark.parametrize("fmt", registry.REGISTRY, ids=lambda f: f"{f.kind}:{f.name}")
def test_every_entry_imports(fmt: Format) -> None:
    """A module renamed or moved without its registry entry fails here."""
    if registry.missing(fmt):
        pytest.skip(f"{fmt.name} needs {registry.missing(fmt)} (eyeq-spi[{fmt.extra}])")
    assert callable(registry.load(fmt))
    if fmt.sniff is not None:
        assert any(name == fmt.sniff for name, _ in registry.sniffers(text=True))
    if fmt.fast is not None:
        mod, _, name = fmt.fast.partition(":")
        assert callable(getattr(importlib.import_module(mod), name))
    assert fmt.suffixes or fmt.kind == registry.CAN_LOG
    assert all(s.startswith(".") and s == s.lower() for s in fmt.suffixes)


def test_registering_imports_no_heavy_library() -> None:
    code = ("import sys, eyeq_spi.io; print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'numpy', 'pandas', 'pyarrow', 'asammdf', 'mcap', 'can', 'cantools', 'orjson', "
            "'yaml', 'eyeq_spi.logic'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_a_missing_extra_names_the_pip_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "asammdf" else real(name, *a))
    with pytest.raises(MissingExtra, match=r"pip install 'eyeq-spi\[export\]'") as exc:
        registry.load("mdf4", RECORD_WRITER)
    assert exc.value.extra == "export"
    fake = Format("fake", RECORD_WRITER, (".fake",), "no_such_module_xyz:Writer", "",
                  extra="fake", needs=("no_such_module_xyz",))
    with pytest.raises(MissingExtra, match=r"eyeq-spi\[fake\]"):
        registry.load(fake)


# -- record writers --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def records(capture: list[Transfer]) -> list[dict[str, Any]]:
    from eyeq_spi.dissect.engine import Dissector

    dis = Dissector()
    out = [r for rec in capture for r in dis.feed(rec)]
    out += list(dis.finish())
    assert any(r["kind"] == "message" and r["fields"] for r in out)
    return out


def _rows(records: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """The table rows of every message (``docs/dissector.md`` tables), every field kept: a
    table per message name, a MESP reply in ``NAME.reply``; a row with a column its
    table's header lacks goes in the next part (``NAME.2``) whose header holds it."""
    from eyeq_spi.dissect.output import flatten, table_name

    out: dict[str, list[dict[str, Any]]] = {}
    headers: dict[str, list[list[str]]] = {}
    for r in records:
        if r["kind"] == "message":
            row = {"file": None, "frame_index": r["frames"][-1], "time": r["time"],
                   "direction": r["direction"],
                   **{f"header.{k}": v for k, v in r["header"].items()}, **flatten(r["fields"])}
            name = table_name(r)
            parts = headers.setdefault(name, [])
            k = next((i for i, h in enumerate(parts) if set(row) <= set(h)), None)
            if k is None:
                parts.append(list(row))
                k = len(parts) - 1
            stem = name if k == 0 else f"{name}.{k + 1}"
            out.setdefault(stem, []).append({c: row.get(c) for c in parts[k]})
    return out


def _jsonl(recs: list[dict[str, Any]], out: Path) -> Any:
    w = registry.load("jsonl", RECORD_WRITER)
    with open(out / "records.jsonl", "w", encoding="utf-8") as fh:
        writer = w(fh)
        for r in recs:
            writer.write(r)
    got = [json.loads(line) for line in (out / "records.jsonl").read_text().splitlines()]
    return got, json.loads(json.dumps(recs))


def _csv(recs: list[dict[str, Any]], out: Path) -> Any:
    w = registry.load("csv", RECORD_WRITER)(str(out), "csv")
    for r in recs:
        w.write(r)
    w.close()
    got = {p.stem: list(csv.DictReader(p.open(encoding="utf-8"))) for p in out.glob("*.csv")}
    text = {name: [{k: "" if v is None else str(v) for k, v in row.items()} for row in rows]
            for name, rows in _rows(recs).items()}
    return got, text


def _parquet(recs: list[dict[str, Any]], out: Path) -> Any:
    import pyarrow.parquet as pq

    w = registry.load("parquet", RECORD_WRITER)(str(out), "parquet")
    for r in recs:
        w.write(r)
    w.close()
    got = {p.stem: pq.read_table(p).to_pylist() for p in out.glob("*.parquet")}
    return got, _rows(recs)


ROUND_TRIPS: dict[str, Callable[[list[dict[str, Any]], Path], Any]] = {
    "jsonl": _jsonl, "csv": _csv, "parquet": _parquet}
READ_BACK_ELSEWHERE = {  # writers whose reading back needs their own library's reader
    "mdf4": "tests/test_logic.py::test_mdf_export_reads_back_with_asammdf",
    "mcap": "tests/test_logic.py::test_mcap_export_reads_back",
}


@pytest.mark.parametrize("fmt", registry.formats(RECORD_WRITER), ids=lambda f: f.name)
def test_record_writer_round_trips_the_records(fmt: Format, records: list[dict[str, Any]],
                                               tmp_path: Path) -> None:
    if fmt.name in READ_BACK_ELSEWHERE:
        test = READ_BACK_ELSEWHERE[fmt.name]
        assert (ROOT / test.split("::")[0]).read_text().count(f"def {test.split('::')[1]}(")
        pytest.skip(f"read back by {test}")
    assert fmt.name in ROUND_TRIPS, f"{fmt.name}: give the test a round trip"
    if registry.missing(fmt):
        pytest.skip(f"{fmt.name} needs {registry.missing(fmt)} (eyeq-spi[{fmt.extra}])")
    got, want = ROUND_TRIPS[fmt.name](records, tmp_path)
    assert got == want


def test_times_survive_the_table_writers(records: list[dict[str, Any]]) -> None:
    """The round trips above compare times exactly: they are the capture's, not rounded."""
    times = [r["time"] for r in records if r["kind"] == "message" and r["fields"]]
    assert times and all(isinstance(t, float) and math.isfinite(t) for t in times)


# -- documentation --------------------------------------------------------------------------
def test_docs_table_is_the_registry() -> None:
    text = (ROOT / "docs" / "captures.md").read_text()
    start = "<!-- formats: generated from eyeq_spi.io -->\n"
    end = "<!-- end of formats -->"
    assert start in text and end in text
    table = text.split(start, 1)[1].split(end, 1)[0]
    assert table == registry.markdown_table(), (
        "docs/captures.md is stale: put the output of python -c 'from eyeq_spi.io import "
        "markdown_table; print(markdown_table(), end=\"\")' between its markers")


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_a_row_with_a_new_column_goes_in_a_new_part_not_lost(fmt: str, tmp_path: Path) -> None:
    """Two releases' variants of one message (other members) in one run: the table's first
    part keeps its header, the row with a member it lacks goes in ``NAME.2``; nothing is lost."""
    if fmt == "parquet":
        pytest.importorskip("pyarrow", reason="the parquet extra (pyarrow) is not installed")
    w = registry.load(fmt, RECORD_WRITER)(str(tmp_path), fmt)

    def rec(i: int, fields: dict[str, Any]) -> dict[str, Any]:
        return {"kind": "message", "name": "M", "protocol": "DASP", "frames": [i], "time": i / 10,
                "direction": "e2h", "header": {"counter": i}, "fields": fields}

    for r in (rec(1, {"a": 1}), rec(2, {"a": 2, "b": 3}), rec(3, {"a": 4}), rec(4, {"b": 5})):
        w.write(r)
    w.close()
    if fmt == "csv":
        got = {p.stem: list(csv.DictReader(p.open(encoding="utf-8")))
               for p in tmp_path.glob("*.csv")}
        assert [r["a"] for r in got["M"]] == ["1", "4"]
        assert [(r["a"], r["b"]) for r in got["M.2"]] == [("2", "3"), ("", "5")]
    else:
        import pyarrow.parquet as pq

        # rows are written in groups: a group's table has every column of its rows, and a later
        # group with a column the file lacks would open M.2 as the CSV does
        rows = [r for p in sorted(tmp_path.glob("M*.parquet"))
                for r in pq.read_table(p).to_pylist()]
        assert sorted(((r["a"], r.get("b")) for r in rows), key=str) == sorted(
            [(1, None), (2, 3), (4, None), (None, 5)], key=str)
        w = registry.load(fmt, RECORD_WRITER)(str(tmp_path / "g"), fmt, batch=1)
        for r in (rec(1, {"a": 1}), rec(2, {"a": 2, "b": 3}), rec(3, {"a": 4})):
            w.write(r)
        w.close()
        got = {p.stem: pq.read_table(p).to_pylist() for p in (tmp_path / "g").glob("*.parquet")}
        assert [r["a"] for r in got["M"]] == [1, 4]
        assert [(r["a"], r["b"]) for r in got["M.2"]] == [(2, 3)]
