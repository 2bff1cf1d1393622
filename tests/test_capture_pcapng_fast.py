"""The pcapng reader's buffer refills (``capture.pcapng_fast``): read into a new buffer after what
is left (``readinto``) or joined (a stream with ``read`` only), the chunks are the same, whole or
cut anywhere (with a ``Tail``), with refills inside blocks and runs."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from eyeq_spi.capture import pcapng_fast
from eyeq_spi.capture.pcapng_fast import pcapng_chunks
from eyeq_spi.capture.pcapng_io import CaptureWriter, Tail
from eyeq_spi.errors import InputError

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1


class _ReadOnly:
    """A stream with ``read`` only (no ``readinto``), in short reads."""

    def __init__(self, blob: bytes) -> None:
        self.f = io.BytesIO(blob)

    def read(self, n: int = -1) -> bytes:
        return self.f.read(min(n, 777) if n >= 0 else n)


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


@pytest.mark.parametrize("read_size", [pcapng_fast.READ_SIZE, 5000, 100])
@pytest.mark.parametrize("cut", [None, 60, 1000, 160 * 700 + 13, -1, -4])
def test_refills_read_the_same_with_readinto_or_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, read_size: int, cut: int | None
) -> None:
    monkeypatch.setattr(pcapng_fast, "READ_SIZE", read_size)
    blob = _capture(tmp_path / "c.pcapng")
    short = blob if cut is None else blob[:cut]
    path = tmp_path / "cut.pcapng"
    path.write_bytes(short)
    for tail_kind in (None, Tail):
        t_file, t_ref = (tail_kind(), tail_kind()) if tail_kind else (None, None)
        with path.open("rb") as fh:
            got = _read(fh, t_file)
        assert got == _read(_ReadOnly(short), t_ref)
        assert t_file == t_ref
        if cut is None:
            assert got[0] == "ok"
