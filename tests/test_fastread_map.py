"""The pcapng reader maps a regular file instead of reading it (``capture/fastread.py``): the same
chunks as from a stream, whole or cut anywhere (with a ``Tail``), and the file's position follows
what was consumed."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from eyeq_spi.capture import fastread
from eyeq_spi.capture.fastread import pcapng_chunks
from eyeq_spi.capture.pcapng_io import CaptureError, CaptureWriter, Tail


def _capture(path: Path) -> bytes:
    rng = np.random.default_rng(7)
    with CaptureWriter(path) as w:
        for i in range(3000):
            size = 128 if i % 97 else int(rng.integers(1, 200))  # runs, and odd blocks between
            w.write("h2e" if i % 3 else "e2h", i * 1e-4, rng.bytes(size))
    return path.read_bytes()


def _flat(chunks: list[fastread.Chunk]) -> tuple[object, ...]:
    return (np.concatenate([c.data for c in chunks]).tobytes(),
            np.concatenate([c.length for c in chunks]).tolist(),
            np.concatenate([c.time for c in chunks]).tolist(),
            np.concatenate([c.direction for c in chunks]).tolist(),
            [sorted(c.odd.items()) for c in chunks])


def _read(src: object, tail: Tail | None) -> tuple[str, object]:
    try:
        return "ok", _flat(list(pcapng_chunks(src, 1000, tail)))  # type: ignore[arg-type]
    except CaptureError as exc:
        return "error", str(exc)


def test_a_mapped_file_gives_the_chunks_of_a_stream(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "c.pcapng"
    blob = _capture(path)
    with path.open("rb") as fh:
        walker_maps: list[bool] = []
        real = fastread._Walker._map

        def spy(self: fastread._Walker, read: int) -> bool:
            walker_maps.append(real(self, read))
            return walker_maps[-1]

        monkeypatch.setattr(fastread._Walker, "_map", spy)
        mapped = _read(fh, None)
        assert walker_maps == [True]
        assert fh.tell() == len(blob)  # the progress bar sees the whole file consumed
    assert mapped == _read(io.BytesIO(blob), None)


@pytest.mark.parametrize("cut", [60, 1000, 160 * 700 + 13, -1, -4])
def test_a_cut_file_reads_the_same_mapped_or_streamed(tmp_path: Path, cut: int) -> None:
    blob = _capture(tmp_path / "c.pcapng")
    short = blob[:cut]
    path = tmp_path / "cut.pcapng"
    path.write_bytes(short)
    for tail_kind in (None, Tail):
        t_map, t_io = (tail_kind(), tail_kind()) if tail_kind else (None, None)
        with path.open("rb") as fh:
            got = _read(fh, t_map)
        assert got == _read(io.BytesIO(short), t_io)
        assert t_map == t_io
