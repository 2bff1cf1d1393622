"""The pcapng reader's buffer refills (``capture.pcapng_fast``): a file, or a stream that gives
short reads (a pipe), reads into the same chunks, whole or cut anywhere (with a ``Tail``), with
refills inside blocks and runs."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from eyeq_spi.capture.pcapng_fast import pcapng_chunks
from eyeq_spi.capture.pcapng_io import CaptureWriter, Tail
from eyeq_spi.errors import InputError

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1


class _Short:
    """A stream that gives at most ``most`` bytes a read, as a pipe may."""

    def __init__(self, blob: bytes, most: int) -> None:
        self.f = io.BytesIO(blob)
        self.most = most

    def read(self, n: int = -1) -> bytes:
        return self.f.read(min(n, self.most) if n >= 0 else self.most)


def _capture(path: Path) -> bytes:
    rng = np.random.default_rng(7)
    with CaptureWriter(path) as w:
        for i in range(3000):
            size = 128 if i % 97 else int(rng.integers(1, 200))  # runs, and odd blocks between
            w.write("h2e" if i % 3 else "e2h", i * 1e-4, rng.bytes(size))
    return path.read_bytes()


def _read(src: object, tail: Tail | None) -> tuple[str, object]:
    try:
        chunks = list(pcapng_chunks(src, 1000, tail))  # type: ignore[arg-type]
    except InputError as exc:
        return "error", str(exc)
    for c in chunks:
        assert all(type(v) is bytes for v in c.odd.values())
    return "ok", (np.concatenate([c.data for c in chunks]).tobytes(),
                  np.concatenate([c.length for c in chunks]).tolist(),
                  np.concatenate([c.time for c in chunks]).tolist(),
                  np.concatenate([c.direction for c in chunks]).tolist(),
                  [sorted(c.odd.items()) for c in chunks])


@pytest.mark.parametrize("most", [5000, 777, 100])
@pytest.mark.parametrize("cut", [None, 60, 1000, 160 * 700 + 13, -1, -4])
def test_short_reads_read_the_same_as_the_file(tmp_path: Path, most: int, cut: int | None
                                               ) -> None:
    blob = _capture(tmp_path / "c.pcapng")
    short = blob if cut is None else blob[:cut]
    path = tmp_path / "cut.pcapng"
    path.write_bytes(short)
    for tail_kind in (None, Tail):
        t_file, t_ref = (tail_kind(), tail_kind()) if tail_kind else (None, None)
        with path.open("rb") as fh:
            got = _read(fh, t_file)
        assert got == _read(_Short(short, most), t_ref)
        assert t_file == t_ref
        if cut is None:
            assert got[0] == "ok"
