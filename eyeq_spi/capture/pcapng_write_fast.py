"""Enhanced Packet Blocks encoded in blocks: the fast twin of ``CaptureWriter._write``.

:class:`~eyeq_spi.capture.pcapng_io.CaptureWriter` in block mode keeps the transfers it is handed
and encodes them here many at a time: per run of transfers of one length, one numpy array of
``(n, block size)`` bytes whose columns are the EPB fields (type 6, total length, interface,
timestamp high and low words, captured and original length, the data, its padding to 4 bytes and
the trailing total length; pcapng §4.3, ``specs/capture.yaml``). The bytes are the ones the
per-transfer encoder writes (``tests/test_capture_pcapng_write_fast.py``); the first block of a
capture carries the release comment and is encoded by the writer itself.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

EPB_TYPE = 6
EPB_FIXED = 32  # type, length, interface, ts high, ts low, caplen, len, trailing length
_MAX_TICKS = float(1 << 62)  # float64 holds these exactly; round() and np.rint agree below


def ticks_of(times: Sequence[float], scale: int) -> np.ndarray | None:
    """``max(0, round(t * scale))`` for every time as int64 (``round`` and ``np.rint`` both
    round half to even), or None when one is not finite or too large (the writer's own
    encoder then raises for it, as it always has)."""
    x = np.rint(np.asarray(times, dtype=np.float64) * scale)
    if not (np.abs(x) < _MAX_TICKS).all():  # NaN compares False too
        return None
    out: np.ndarray = np.maximum(x, 0.0).astype(np.int64)
    return out


def encode_run(ids: Sequence[int], ticks: np.ndarray, data: Sequence[bytes], length: int
               ) -> bytes:
    """The EPBs of ``len(data)`` transfers all ``length`` bytes long, concatenated."""
    n = len(data)
    pad = -length % 4
    size = EPB_FIXED + length + pad
    out = np.zeros((n, size), dtype=np.uint8)
    head = np.empty((n, 7), dtype="<u4")
    head[:, 0] = EPB_TYPE
    head[:, 1] = size
    head[:, 2] = ids
    head[:, 3] = ticks >> 32
    head[:, 4] = ticks & 0xFFFFFFFF
    head[:, 5] = length
    head[:, 6] = length
    out[:, :28] = head.view(np.uint8).reshape(n, 28)
    if length:
        out[:, 28:28 + length] = np.frombuffer(b"".join(data), dtype=np.uint8).reshape(n, length)
    out[:, size - 4:] = np.frombuffer(size.to_bytes(4, "little"), dtype=np.uint8)
    return out.tobytes()


def encode_blocks(ids: Sequence[int], ticks: np.ndarray, data: Sequence[bytes]) -> bytes:
    """The EPBs of transfers of any lengths, in order: one :func:`encode_run` per run of
    consecutive transfers of one length."""
    parts: list[bytes] = []
    n = len(data)
    start = 0
    while start < n:
        length = len(data[start])
        end = start + 1
        while end < n and len(data[end]) == length:
            end += 1
        parts.append(encode_run(ids[start:end], ticks[start:end], data[start:end], length))
        start = end
    return b"".join(parts)
