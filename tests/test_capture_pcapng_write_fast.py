"""The capture writer in block mode (``capture.pcapng_write_fast``): the file holds the bytes the
per-transfer writer writes, whatever the lengths, times and flush instants, and a run that stops
or raises still finds every transfer it handed over on disk."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eyeq_spi.capture.pcapng_io import CaptureWriter, read_pcapng

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

_TIMES = st.one_of(
    st.floats(-1.0, 1e6, allow_nan=False),
    st.integers(0, 10**9).map(lambda k: k * 0.5e-6),  # ties at half a tick: round half to even
    st.floats(0.0, 4e12, allow_nan=False))  # past 2**32 µs: the timestamp's high word
_TRANSFER = st.one_of(st.binary(min_size=128, max_size=128), st.binary(max_size=140))
_RECORDS = st.lists(st.tuples(st.sampled_from(["h2e", "e2h"]), _TIMES, _TRANSFER,
                              st.floats(0.0, 0.7)), max_size=60)


def _records(path: Path) -> list[Any]:
    with path.open("rb") as fh:
        return list(read_pcapng(fh))


def _write(path: Path, blocks: bool, records: list[tuple[str, float, bytes, float]],
           flush_every: int = 0) -> bytes:
    now = [0.0]
    with CaptureWriter(path, "8.1", clock=lambda: now[0], idle_flush=False,
                       blocks=blocks) as w:
        for k, (direction, t, data, dt) in enumerate(records):
            now[0] += dt  # the wall clock: some writes come after the flush interval
            w.write(direction, t, data)
            if flush_every and k % flush_every == flush_every - 1:
                w.flush()
    return path.read_bytes()


@settings(max_examples=150, deadline=None)
@given(_RECORDS, st.integers(0, 7))
def test_block_writer_writes_the_bytes_of_the_per_transfer_writer(
        tmp_path_factory: pytest.TempPathFactory, records: list[Any], flush_every: int) -> None:
    d = tmp_path_factory.mktemp("w")
    want = _write(d / "one.pcapng", False, records, flush_every)
    assert _write(d / "blocks.pcapng", True, records, flush_every) == want


def test_a_long_run_of_full_transfers_is_byte_identical(tmp_path: Path) -> None:
    """Thousands of transfers (several 64 KiB flushes), a few odd lengths between."""
    records = [("h2e" if i % 3 else "e2h", 12.5 + i * 3.7e-4,
                bytes([i & 0xFF]) * (128 if i % 211 else 37), 0.0) for i in range(5000)]
    assert _write(tmp_path / "a", True, records) == _write(tmp_path / "b", False, records)


def test_block_mode_encodes_many_transfers_at_once(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """After the first transfer (it carries the release comment) none is encoded alone."""
    calls: list[int] = []
    orig = CaptureWriter._encode_one

    def count(self: CaptureWriter, *args: Any) -> None:
        calls.append(1)
        orig(self, *args)

    monkeypatch.setattr(CaptureWriter, "_encode_one", count)
    with CaptureWriter(tmp_path / "c.pcapng", idle_flush=False, blocks=True) as w:
        for i in range(1000):
            w.write("h2e", i * 1e-3, bytes(128))
    assert calls == [1]
    assert len(_records(tmp_path / "c.pcapng")) == 1000


def test_a_run_that_raises_still_writes_every_transfer_handed_over(tmp_path: Path) -> None:
    """The emulator with ``--capture``: a node raises in the middle of the run; closing the
    writer (as ``demo`` does in its ``finally``) puts every tapped transfer on disk."""
    from eyeq_spi.emulator import build

    path = tmp_path / "raise.pcapng"
    writer = CaptureWriter(path, idle_flush=False, blocks=True)
    tapped: list[tuple[str, float, bytes]] = []

    def tap(node: int, t: float, transfer: bytes) -> None:
        direction = "h2e" if node == 0 else "e2h"
        tapped.append((direction, t, bytes(transfer)))
        writer.write(direction, t, transfer)

    emu = build(keep_rx_times=False, tap=tap)
    sim = emu.runner.nodes[1][0]
    real = sim.handle_timer

    def boom(now: float) -> None:
        if now > 1.2:
            raise RuntimeError("node failed")
        real(now)

    sim.handle_timer = boom
    with pytest.raises(RuntimeError, match="node failed"):
        try:
            emu.run_for(5.0)
        finally:
            writer.close()
    assert len(tapped) > 100
    got = _records(path)
    assert [(r.direction, r.data) for r in got] == [(d, x) for d, _, x in tapped]
    assert [r.time for r in got] == pytest.approx([t for _, t, _ in tapped], abs=1e-6)


@pytest.mark.parametrize("blocks", [False, True])
def test_a_time_without_a_timestamp_is_a_capture_error_and_the_rest_is_written(
        tmp_path: Path, blocks: bool) -> None:
    """NaN, infinity or a time past 2**64 µs: one typed error (at the write, or at the flush
    that encodes it in block mode); every other transfer reaches the file."""
    from eyeq_spi.errors import OutputError

    path = tmp_path / "bad.pcapng"
    w = CaptureWriter(path, idle_flush=False, blocks=blocks)
    errors = []
    for i, t in enumerate([0.0, 1e-3, float("nan"), 2e-3, float("inf"), 3e-3, 2e14, 4e-3]):
        try:
            w.write("h2e", t, bytes([i]) * 128)
        except OutputError as exc:
            errors.append(str(exc))
    try:
        w.close()
    except OutputError as exc:
        errors.append(str(exc))
    assert errors and all("has no pcapng timestamp" in e for e in errors)
    got = [r.data[0] for r in _records(path)]
    assert got == [0, 1, 3, 5, 7]


def _write_many(path: Path, blocks: bool, records: list[tuple[str, float, bytes, float]],
                cuts: list[int]) -> bytes:
    """The records handed over in runs (``write_many``), cut at ``cuts``."""
    now = [0.0]
    edges = [0, *sorted(c % (len(records) + 1) for c in cuts), len(records)]
    with CaptureWriter(path, "8.1", clock=lambda: now[0], idle_flush=False,
                       blocks=blocks) as w:
        for a, b in itertools.pairwise(edges):
            now[0] += sum(dt for *_, dt in records[a:b])
            w.write_many([(d, t, data) for d, t, data, _ in records[a:b]])
    return path.read_bytes()


@settings(max_examples=100, deadline=None)
@given(_RECORDS, st.lists(st.integers(0, 60), max_size=6), st.booleans())
def test_runs_handed_over_at_once_write_the_bytes_of_single_writes(
        tmp_path_factory: pytest.TempPathFactory, records: list[Any], cuts: list[int],
        blocks: bool) -> None:
    """``write_many`` (a message handover's transfers, from the emulator's tap) gives the file
    ``write`` gives, in both modes, the first transfer (it carries the comment) inside a run."""
    d = tmp_path_factory.mktemp("m")
    want = _write(d / "one.pcapng", False, records)
    assert _write_many(d / "many.pcapng", blocks, records, cuts) == want


def test_the_demo_capture_equals_the_reference(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``demo --virtual-time --capture``: the file is the reference writer's, byte for byte."""
    from eyeq_spi.cli import main

    fast, ref = tmp_path / "fast.pcapng", tmp_path / "ref.pcapng"
    args = ["demo", "--virtual-time", "--duration", "1.5", "--objects", "5", "--json"]
    assert main([*args, "--capture", str(fast)]) == 0
    monkeypatch.setenv("EYEQ_SPI_EXACT", "1")
    assert main([*args, "--capture", str(ref)]) == 0
    assert fast.read_bytes() == ref.read_bytes()
