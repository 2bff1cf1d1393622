"""The sigrok session file (``export --sr``): libsigrok's srzip layout, and samples that carry
every transfer's bytes at its capture time, read back here without sigrok."""

from __future__ import annotations

import configparser
import zipfile
from pathlib import Path

import numpy as np
import pytest

from eyeq_spi import io as formats
from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.cli import main
from eyeq_spi.logic.options import SpiOptions
from eyeq_spi.logic.sr_write import CHUNK, LEAD, samplerate_text, write_sr


def _transfers() -> list[Transfer]:
    rng = np.random.default_rng(7)
    recs = []
    for k in range(40):
        d = "h2e" if k % 2 == 0 else "e2h"
        # the two channels overlap in time; a pause of 0.3 s spans several chunks
        t = 1000.0 + 0.001 * (k // 2) + (0.3 if k >= 20 else 0.0) + (0.00002 if d == "e2h" else 0.0)
        recs.append(Transfer(t, d, rng.integers(0, 256, 128, dtype=np.uint8).tobytes()))
    return recs


def _read(path: Path) -> tuple[configparser.ConfigParser, np.ndarray]:
    with zipfile.ZipFile(path) as zf:
        assert zf.read("version") == b"2"
        meta = configparser.ConfigParser()
        meta.read_string(zf.read("metadata").decode())
        names = [n for n in zf.namelist() if n.startswith("logic-1-")]
        assert names == [f"logic-1-{k}" for k in range(1, len(names) + 1)]
        assert all(zf.getinfo(n).compress_type == zipfile.ZIP_DEFLATED for n in names)
        assert all(zf.getinfo(n).file_size <= CHUNK for n in names)
        samples = np.frombuffer(b"".join(zf.read(n) for n in names), dtype=np.uint8)
    return meta, samples


def _decode(samples: np.ndarray, probes: dict[str, int], d: str, rate: float
            ) -> list[tuple[float, bytes]]:
    """SPI mode 1 by hand: MOSI read on every falling CLK edge while CS is low."""
    bit = {s: (samples >> probes[f"{d}_{s}"]) & 1 for s in ("cs", "clk", "mosi")}
    cs_edges = np.flatnonzero(np.diff(bit["cs"].astype(np.int8)))
    out = []
    for fall, rise in zip(cs_edges[0::2] + 1, cs_edges[1::2] + 1, strict=True):
        clk = bit["clk"][fall:rise].astype(np.int8)
        falling = np.flatnonzero(np.diff(clk) == -1) + 1
        bits = bit["mosi"][fall:rise][falling]
        out.append((fall / rate, np.packbits(bits).tobytes()))
    return out


def test_session_file_holds_every_transfer_at_its_time(tmp_path: Path) -> None:
    recs = _transfers()
    path = tmp_path / "x.sr"
    w = write_sr(recs, path, SpiOptions())
    assert w.count == len(recs)
    meta, samples = _read(path)
    dev = meta["device 1"]
    assert dev["capturefile"] == "logic-1" and dev["unitsize"] == "1"
    assert dev["samplerate"] == "20 MHz" and int(dev["total probes"]) == 8
    probes = {dev[f"probe{k}"]: k - 1 for k in range(1, 9)}
    assert len(samples) > 0.3 * 20e6  # the pause is in the samples: times are capture times
    for d in ("h2e", "e2h"):
        mine = [r for r in recs if r.direction == d]
        got = _decode(samples, probes, d, 20e6)
        assert [data for _, data in got] == [r.data for r in mine]
        first = recs[0].time
        assert [t - LEAD / 20e6 for t, _ in got] == pytest.approx(
            [r.time - first for r in mine], abs=1e-7)


def test_registered_and_exported(tmp_path: Path) -> None:
    assert formats.get("sr", formats.CAPTURE_WRITER).suffixes == (".sr",)
    write = formats.load("sr", formats.CAPTURE_WRITER)
    assert write(_transfers()[:4], tmp_path / "y.sr") == 4
    cap = tmp_path / "c.hex"
    cap.write_text("0.0 h2e " + "00" * 128 + "\n0.001 e2h " + "ff" * 128 + "\n")
    assert main(["export", str(cap), "--sr", str(tmp_path / "c.sr")]) == 0
    _meta, samples = _read(tmp_path / "c.sr")
    assert len(samples) > 0.001 * 20e6


def test_samplerate_words() -> None:
    assert [samplerate_text(x) for x in (20_000_000, 500_000, 1234)] == [
        "20 MHz", "500 kHz", "1234 Hz"]


def test_max_idle_shortens_the_pause_and_says_so(tmp_path: Path) -> None:
    recs = _transfers()
    path = tmp_path / "short.sr"
    write_sr(recs, path, SpiOptions(), max_idle=0.0001)
    meta, samples = _read(path)
    assert len(samples) < 0.05 * 20e6  # the 0.3 s pause is gone
    with zipfile.ZipFile(path) as zf:
        assert "times are not capture times" in zf.read("metadata").decode()
    probes = {meta["device 1"][f"probe{k}"]: k - 1 for k in range(1, 9)}
    for d in ("h2e", "e2h"):  # every transfer still there, in order
        got = [data for _, data in _decode(samples, probes, d, 20e6)]
        assert got == [r.data for r in recs if r.direction == d]
