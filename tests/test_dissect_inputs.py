"""Dissector input hardening: truncated, foreign and empty files are a one-line InputError,
over-long hex lines are refused with their line number, and memory stays bounded for
pathological inputs (the readers never ask for more than a bounded number of bytes)."""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eyeq_spi.capture.pcapng_io import MAX_BLOCK, CaptureWriter
from eyeq_spi.errors import InputError
from eyeq_spi.io.plain import MAX_HEX_LINE, open_transfers


@pytest.fixture(scope="module")
def pcapng_bytes(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    path = tmp_path_factory.mktemp("pcap") / "small.pcapng"
    with CaptureWriter(path) as w:
        for i in range(6):
            w.write("h2e" if i % 2 else "e2h", i * 0.001, bytes([i]) * 128)
    return path.read_bytes()


def _blocks(data: bytes) -> list[int]:
    """Offsets where a pcapng block starts (and the end of the file)."""
    out, pos = [], 0
    while pos < len(data):
        out.append(pos)
        pos += struct.unpack_from("<I", data, pos + 4)[0]
    return [*out, len(data)]


def _read_all(data: bytes, fmt: str | None = None) -> list[object]:
    _, records = open_transfers(io.BytesIO(data), fmt)
    return list(records)


def test_the_whole_capture_reads(pcapng_bytes: bytes) -> None:
    assert len(_read_all(pcapng_bytes)) == 6


def test_every_cut_inside_a_block_is_truncated(pcapng_bytes: bytes) -> None:
    bounds = set(_blocks(pcapng_bytes))
    for cut in range(1, len(pcapng_bytes)):
        if cut in bounds:
            continue
        with pytest.raises(InputError, match=r"^(truncated|malformed) pcapng|^input of"):
            _read_all(pcapng_bytes[:cut])  # under 4 bytes it is not even recognised


def test_a_cut_between_blocks_keeps_the_whole_transfers(pcapng_bytes: bytes) -> None:
    bounds = _blocks(pcapng_bytes)
    # SHB + 2 IDBs, then one EPB per transfer
    assert len(_read_all(pcapng_bytes[:bounds[-2]])) == 5
    with pytest.raises(InputError, match="without any transfer"):
        _read_all(pcapng_bytes[:bounds[3]])


@pytest.mark.parametrize("data", [b"", b"\x0a\x0d\x0d\x0a", b"\x0a\x0d\x0d\x0a\x1c\x00\x00\x00",
                                  b"%PDF-1.7\n" + b"x" * 500, b"\x89PNG\r\n\x1a\n" + bytes(300),
                                  b"\x0a\x0d\x0d\x0a" + b"\xff" * 40, b"# only a comment\n",
                                  b"\xd4\xc3\xb2\xa1" + bytes(60)])
def test_empty_and_foreign_inputs_are_one_line_errors(data: bytes) -> None:
    with pytest.raises(InputError) as info:
        _read_all(data)
    assert "\n" not in str(info.value) and str(info.value)


class _Endless(io.RawIOBase):
    """An endless stream of one byte pattern that counts what is read from it."""

    def __init__(self, head: bytes, fill: bytes) -> None:
        self.head, self.fill, self.served = head, fill, 0

    def readable(self) -> bool:
        return True

    def read(self, n: int = -1) -> bytes:
        if n is None or n < 0:
            raise AssertionError("an unbounded read")
        if self.head:
            out, self.head = self.head[:n], self.head[n:]
        else:
            out = (self.fill * (n // len(self.fill) + 1))[:n]
        self.served += len(out)
        return out


def test_an_endless_hex_line_is_refused_with_its_line_number_after_bounded_reading() -> None:
    good = b"0.0 h2e " + b"00" * 128 + b"\n"
    stream = _Endless(good * 3, b"ab")
    with pytest.raises(InputError, match=rf"^line 4: longer than {MAX_HEX_LINE} characters"):
        for _ in open_transfers(stream, "hex")[1]:  # type: ignore[arg-type]
            pass
    assert stream.served < MAX_HEX_LINE + (1 << 17)


def test_a_huge_pcapng_block_length_is_refused_before_it_is_read(pcapng_bytes: bytes) -> None:
    head = pcapng_bytes[:_blocks(pcapng_bytes)[3]] + struct.pack("<II", 6, 0xFFFFFFF0)
    stream = _Endless(head, b"\x00")
    with pytest.raises(InputError, match="limit"):
        for _ in open_transfers(stream, "pcapng")[1]:  # type: ignore[arg-type]
            pass
    assert stream.served < MAX_BLOCK


@given(st.binary(min_size=0, max_size=600))
def test_any_bytes_after_the_magic_give_records_or_one_input_error(tail: bytes) -> None:
    try:
        _read_all(b"\x0a\x0d\x0d\x0a" + tail)
    except InputError as exc:
        assert "\n" not in str(exc)


def test_the_cli_names_the_reason_in_one_line(pcapng_bytes: bytes, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    from eyeq_spi.cli import main

    cases: dict[str, bytes] = {
        "four.pcapng": pcapng_bytes[:4], "cut.pcapng": pcapng_bytes[:-7], "empty.bin": b"",
        "long.hex": b"00" * (MAX_HEX_LINE + 1) + b"\n",
    }
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        # a pcapng cut inside a block is read up to its last whole block: a finding (exit 1)
        assert main(["dissect", str(tmp_path / name)]) == (1 if name == "cut.pcapng" else 2), \
            name
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err, err


def _lines(n: int) -> Iterator[bytes]:
    for i in range(n):
        yield f"{i * 0.001:.3f} h2e ".encode() + bytes([i % 256]).hex().encode() * 128 + b"\n"


def test_hex_lines_up_to_the_limit_read(tmp_path: Path) -> None:
    data = b"".join(_lines(5)) + b"# a comment\n" + b"00" * 128 + b"\n"
    assert len(_read_all(data, "hex")) == 6


def test_a_file_that_is_not_a_vcd_is_named_so(tmp_path: Path) -> None:
    """``--format vcd`` on a file that is not a VCD says so (not "truncated VCD")."""
    import subprocess
    import sys

    f = tmp_path / "x.pcapng"
    f.write_bytes(b"\x0a\x0d\x0d\x0a" + bytes(200))
    r = subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "dissect", str(f), "--format",
                        "vcd"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "not a VCD file" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
