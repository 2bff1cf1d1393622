"""The fast path's records for ``dissect --stats`` alone (no fields) and one table writer
(columns): ``--stats`` (text and JSON, key order included), the tables and the exit code are
those of the reference on clean, link-faulty and application-faulty captures; and what the CLI
does around it: the paced garbage collector, the Parquet writer's dictionaries."""

from __future__ import annotations

import gc
import io
import json
import sys
import weakref
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eyeq_spi import garbage
from eyeq_spi.capture.pcapng_fast import chunks_from_transfers
from eyeq_spi.capture.pcapng_io import CaptureWriter, Transfer
from eyeq_spi.cli import main
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect import engine, output, pipeline, pipeline_fast
from eyeq_spi.dissect import engine_fast as batch
from eyeq_spi.dissect.engine_fast_frames import FrameBlock
from eyeq_spi.dissect.stats import Stats
from eyeq_spi.io import plain as inputs
from eyeq_spi.transport.segment import segment
from tests.test_codec_message_fast import _capture
from tests.test_dissect_engine_fast import BASE, MUTATIONS, Rec, _as_records, synthetic
from tests.test_dissect_pipeline_fast import _Pipe

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

CAT = MessageCodec().cat


def _stats_text(st: Stats) -> tuple[str, str]:
    st.finish()
    return json.dumps(st.as_dict()), st.render()  # json.dumps keeps the key order


def exact_stats(recs: list[Transfer]) -> tuple[str, str]:
    st = Stats(CAT)
    for r in engine.iter_records(recs):
        st.add(r)
    return _stats_text(st)


def lean_stats(recs: list[Transfer], chunk: int) -> tuple[str, str]:
    """--stats from the fast path's blocks, in the mode ``dissect --stats`` takes (no fields)."""
    st = Stats(CAT)
    fields = pipeline.fields_mode([], True)
    for item in batch.iter_items(chunks_from_transfers(recs, chunk), fields=fields):
        if isinstance(item, FrameBlock):
            pipeline_fast.consume(item, lambda r: True, True, st, [])
        else:
            st.add(item)
    return _stats_text(st)


@pytest.mark.parametrize("chunk", [5, 64, 1 << 15])
def test_lean_stats_of_a_clean_capture(chunk: int) -> None:
    recs = _as_records(synthetic(12))
    assert lean_stats(recs, chunk) == exact_stats(recs)


@pytest.mark.parametrize("name", sorted(MUTATIONS))
def test_lean_stats_under_each_link_fault(name: str) -> None:
    for i, chunk in ((40, 1 << 15), (150, 16)):
        recs = _as_records(MUTATIONS[name](BASE, min(i, len(BASE) - 1)))
        assert lean_stats(recs, chunk) == exact_stats(recs), (name, i, chunk)


@settings(max_examples=20, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 39), st.integers(1, 7)), max_size=6),
       st.sampled_from([7, 64, 1 << 15]))
def test_lean_stats_under_application_faults(faults: list[tuple[int, int]], chunk: int
                                             ) -> None:
    """E2E, counter gaps, reserved bytes, bad enums, wrong lengths, unknown IDs: the records
    of the faulty messages and the counts of the others give the exact statistics."""
    recs = _capture(faults)
    assert lean_stats(recs, chunk) == exact_stats(recs)


@settings(max_examples=10, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(sorted(MUTATIONS)), st.integers(0, 10**6)),
                min_size=1, max_size=4),
       st.sampled_from([3, 17, 1 << 15]))
def test_lean_stats_under_mixed_link_faults(ops: list[tuple[str, int]], chunk: int) -> None:
    items: list[Rec] = BASE
    for name, where in ops:
        if len(items) < 2:
            break
        items = MUTATIONS[name](items, where % len(items))
    recs = _as_records(items)
    assert lean_stats(recs, chunk) == exact_stats(recs)


# -- the CLI: file (batch path) against stdin (exact path) ------------------------------------
def _big(recs: list[Transfer], transfers: int) -> list[Transfer]:
    """``recs`` again and again, each time later than the last, until ``transfers`` transfers:
    a file that big takes the fast path (``dissect``'s threshold is ``pipeline.SMALL_INPUT``)."""
    out: list[Transfer] = []
    span = max(r.time or 0.0 for r in recs) + 1.0
    while len(out) < transfers:
        shift = len(out) // len(recs) * span
        out += [Transfer(None if r.time is None else r.time + shift, r.direction, r.data)
                for r in recs]
    return out


def _pcapng(recs: list[Transfer], path: Path) -> Path:
    with CaptureWriter(path) as w:
        for r in _big(recs, pipeline.SMALL_INPUT // 150):  # 160 bytes a 128-byte transfer
            w.write(r.direction, r.time, r.data)
    assert path.stat().st_size >= pipeline.SMALL_INPUT
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> list[tuple[Path, list[str]]]:
    tmp = tmp_path_factory.mktemp("lean")
    faulty = BASE
    for name, where in (("flip", 30), ("drop", 90), ("late", 200), ("reset", 300)):
        faulty = MUTATIONS[name](faulty, where)
    app = _capture([(3, 1), (8, 2), (12, 4), (17, 5), (21, 7)])
    raw = tmp / "e2h.bin"
    raw.write_bytes(b"".join(r.data for r in _big(app, pipeline.SMALL_INPUT // 128)))
    return [(_pcapng(_as_records(faulty), tmp / "faulty.pcapng"), []),
            (_pcapng(app, tmp / "app.pcapng"), []), (raw, ["--direction", "e2h"])]




def _run(args: list[str], capsys: pytest.CaptureFixture[str], stdin: bytes | None = None,
         monkeypatch: pytest.MonkeyPatch | None = None) -> tuple[int, str]:
    capsys.readouterr()
    if stdin is None:
        return main(args), capsys.readouterr().out
    assert monkeypatch is not None
    with monkeypatch.context() as m:
        m.setattr(sys, "stdin", io.TextIOWrapper(io.BufferedReader(_Pipe(stdin))))
        rc = main(args)
    return rc, capsys.readouterr().out


@pytest.mark.parametrize("mode", [["--stats"], ["--stats", "--json"], ["--json"]])
def test_cli_batch_and_exact_print_the_same(files: list[tuple[Path, list[str]]],
                                            mode: list[str], capsys: pytest.CaptureFixture[str],
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """Files big enough for the fast path, against the same bytes from a pipe (the
    reference)."""
    for path, extra in files:
        rc, out = _run(["dissect", str(path), *extra, *mode], capsys)
        got = (rc, out.replace(str(path), "-"))  # every record's file
        want = _run(["dissect", "-", *extra, *mode], capsys, path.read_bytes(), monkeypatch)
        assert got == want, path.name
        assert got[0] == 1  # the faults are protocol errors


def test_cli_tables_batch_and_exact(files: list[tuple[Path, list[str]]], tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str],
                                    monkeypatch: pytest.MonkeyPatch) -> None:
    pq = pytest.importorskip("pyarrow.parquet", reason="--parquet needs pyarrow (extra)")
    for k, (path, extra) in enumerate(files):
        for fmt in ("csv", "parquet"):
            b, e = tmp_path / f"{k}{fmt}b", tmp_path / f"{k}{fmt}e"
            rb = _run(["dissect", str(path), *extra, f"--{fmt}", str(b)], capsys)[0]
            re_ = _run(["dissect", "-", *extra, f"--{fmt}", str(e)], capsys, path.read_bytes(),
                       monkeypatch)[0]
            assert rb == re_
            names = sorted(p.name for p in e.iterdir())
            assert names and names == sorted(p.name for p in b.iterdir())
            for n in names:
                if fmt == "csv":  # the file column names the file, or - for stdin
                    got = (b / n).read_bytes().replace(str(path).encode(), b"-")
                    assert got == (e / n).read_bytes(), n
                else:
                    x, y = pq.read_table(b / n), pq.read_table(e / n)
                    assert x.column("file").to_pylist() == [str(path)] * x.num_rows
                    assert y.column("file").to_pylist() == ["-"] * y.num_rows
                    x, y = x.drop_columns(["file"]), y.drop_columns(["file"])
                    assert x.schema.equals(y.schema) and x.equals(y), n


# -- around it -------------------------------------------------------------------------------
class _Node:
    other: Any


def test_paced_gc_frees_cycles_while_the_collector_is_off() -> None:
    """With the automatic collector off, as during a read, cycles made while records stream
    are still freed as the records go by: memory stays bounded."""
    refs: list[weakref.ref[_Node]] = []

    def records() -> Any:
        for _ in range(4 * pipeline.PACE):
            a, b = _Node(), _Node()
            a.other, b.other = b, [a, [[] for _ in range(8)]]  # a cycle of a dozen containers
            refs.append(weakref.ref(a))
            del a, b
            yield {"kind": "frame"}

    alive = -1
    with garbage.paused():
        for n, _ in enumerate(pipeline.paced_gc(records())):
            if n == 3 * pipeline.PACE:
                alive = sum(r() is not None for r in refs[: pipeline.PACE])
        gc.collect()
    assert alive == 0


def test_dissect_leaves_the_collector_as_it_found_it(files: list[tuple[Path, list[str]]],
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    path, extra = files[0]
    assert gc.isenabled()
    main(["dissect", str(path), *extra, "--stats"])
    assert gc.isenabled()
    gc.disable()
    try:
        main(["dissect", str(path), *extra, "--stats"])
        assert not gc.isenabled()
    finally:
        gc.enable()
    main(["dissect", "/nonexistent.pcapng", "--stats"])  # an error on the way out
    assert gc.isenabled()
    capsys.readouterr()


def test_parquet_dictionaries_only_for_words(tmp_path: Path) -> None:
    pq = pytest.importorskip("pyarrow.parquet", reason="--parquet needs pyarrow (extra)")
    w = output.TableWriter(str(tmp_path), "parquet")
    for r in engine.iter_records(_capture([])):
        w.write(r)
    w.close()
    meta = pq.ParquetFile(tmp_path / "EYEQ_VIS_FAILSAFE_MSG.parquet").metadata
    rg = meta.row_group(0)
    dicts = {rg.column(i).path_in_schema: rg.column(i).has_dictionary_page
             for i in range(rg.num_columns)}
    assert dicts["direction"] and dicts["file"] and not dicts["frame_index"]
    assert sum(dicts.values()) == 2


def test_no_group_is_judged_across_a_switch_application_request() -> None:
    """§7.1.1.1.4: after a SwitchEyeQApplication request the host's E2E rolling counters may
    start over; the exact engine may judge the messages after it afresh, so the fast path
    (records and lean counts) judges the messages on each side of it apart, in order."""
    mc = MessageCodec()
    fc = batch.Dissector().frames
    e2e = {"a": E2EState(), "b": E2EState()}
    zero = mc.layout(mc.message("HOST_VEH_STATE_MSG")).zero_values()
    recs: list[Transfer] = []
    num, t = 0, 0.0

    def put(msg: bytes) -> None:
        nonlocal num, t
        for part in segment(msg, 0):
            recs.append(Transfer(round(t, 6), "h2e", fc.data_frame(0, num, part)))
            num, t = (num + 1) % 4096, t + 0.0003

    for i in range(30):
        put(mc.encode_dasp("HOST_VEH_STATE_MSG", zero, i, e2e["a"]))
    put(mc.mesp.encode_request("SwitchEyeQApplication", 1, {"applicationId": 1}))
    for i in range(30, 60):  # the host's E2E counters start over (a fresh state)
        put(mc.encode_dasp("HOST_VEH_STATE_MSG", zero, i, e2e["b"]))
    want = list(engine.iter_records(recs))
    for chunk in (7, 1 << 15):
        assert list(batch.iter_records(chunks_from_transfers(recs, chunk))) == want
        assert lean_stats(recs, chunk) == exact_stats(recs)
    dec = batch.ChunkFeeder().decode
    assert dec.is_barrier(mc.mesp.encode_request("SwitchEyeQApplication", 1,
                                                 {"applicationId": 1}))
    assert not dec.is_barrier(mc.mesp.encode_reply("SwitchEyeQApplication", 1, 0,
                                                   {"applicationId": 1}))


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(sorted(inputs._BINARY_LEAD)),
       # text formats, whole and without their first character (the lead byte completes it
       # where that byte could start a text)
       st.sampled_from([t[k:] for t in (b"$date today $end\n", b"Time [s],Packet ID,MOSI\n",
                                        b"0.5 e2h 08000000 0000 0102030405060708\n",
                                        b"META samplerate: 1\n$var wire 1 ! cs $end\n",
                                        b"\xef\xbb\xbfTime [s],x\n") for k in (0, 1)]),
       st.binary(max_size=300))
def test_a_binary_first_byte_skips_only_text_sniffers_that_cannot_match(
        lead: int, text: bytes, rest: bytes) -> None:
    """detect() skips the logic-analyzer and hex sniffers for a head whose first byte no text
    format starts with (every raw capture: 0x04 ACK, 0x08 DATA): same answer or same error."""
    def run(head: bytes, sniff: bool) -> str:
        try:
            return inputs._detect(head, sniff)
        except inputs.InputError as exc:
            return f"error: {exc}"

    for head in (bytes([lead]) + text + rest, bytes([lead]) + rest + text):
        assert run(head, True) == run(head, False)
    frames = b"".join(r.data for r in _capture([])[:8])
    assert inputs.detect(frames) == "raw" and frames[0] in inputs._BINARY_LEAD
