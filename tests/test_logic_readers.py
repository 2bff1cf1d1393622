"""The logic-analyzer readers on random exports (Saleae) and waveforms in sigrok's layout (VCD),
read in random chunk sizes: the same records or the same typed error whatever the chunking;
bounded memory and line-numbered errors."""

from __future__ import annotations

import io
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.errors import InputError
from eyeq_spi.logic.options import SpiOptions
from eyeq_spi.logic.saleae import read_saleae1, read_saleae2
from eyeq_spi.logic.vcd import read_vcd
from eyeq_spi.logic.vcd_write import write_vcd

Reader = Callable[..., Iterator[Transfer]]


def _both(read: Reader, data: bytes, opts: SpiOptions, chunk: int
          ) -> tuple[list[Transfer] | str, list[Transfer] | str]:
    """(read in chunks of ``chunk`` bytes, read in 1 MiB chunks): the records, or the error's
    text."""

    def run(size: int) -> list[Transfer] | str:
        try:
            return list(read(io.BytesIO(data), opts, chunk_size=size))
        except InputError as exc:
            return f"error: {exc}"

    return run(chunk), run(1 << 20)


SALEAE2, SALEAE1, VCD = read_saleae2, read_saleae1, read_vcd


def _cell(draw: Any, v: int | None) -> str:
    if v is None:
        return draw(st.sampled_from(["", '""']))
    text = draw(st.sampled_from([f"0x{v:02X}", f"0x{v:02x}", f"0X{v:02X}", f'"0x{v:02X}"']))
    return text if draw(st.integers(0, 30)) else str(v)  # now and then a decimal radix


@st.composite
def saleae2_exports(draw: Any) -> bytes:
    rows = ['name,type,start_time,duration,"mosi","miso"']
    t = 0.0
    for _ in range(draw(st.integers(0, 12))):
        name = draw(st.sampled_from(["h2e", "e2h", '"h2e"', '"e2h"']))
        q = draw(st.sampled_from(['"', ""]))
        extra = draw(st.sampled_from(["", "", "", "cut", "reopen", "unclosed", "odd"]))
        if extra == "cut":  # bytes of a transfer the capture cut at its start
            rows.append(f'{name},{q}result{q},{t!r},8e-07,0x01,0x02')
        rows.append(f"{name},{q}enable{q},{t!r},2e-08,,")
        for _ in range(draw(st.integers(0, 2)) if extra == "reopen" else 0):
            rows.append(f'{name},{q}result{q},{t!r},8e-07,0x03,')
            rows.append(f"{name},{q}enable{q},{t!r},2e-08,,")
        for b in draw(st.lists(st.integers(0, 255), max_size=20)):
            miso = draw(st.one_of(st.none(), st.integers(0, 255)))
            rows.append(f"{name},{q}result{q},{t + 1e-6:.9f},8e-07,{_cell(draw, b)},"
                        f"{_cell(draw, miso)}")
        if extra == "odd":
            rows.append(draw(st.sampled_from([f"{name},Result,1,1,0x05,", "", " ",
                                              f'{name},"res,ult",1,1,,', f"{name},result,1",
                                              '"h2e"x,result,1,1,0x01,']))
                        )
        if extra != "unclosed":
            rows.append(f"{name},{q}disable{q},{t + 1e-4!r},2e-08,,")
        t += 1e-3
    end = draw(st.sampled_from(["\n", "\r\n"]))
    return (end.join(rows) + draw(st.sampled_from([end, ""]))).encode()


@st.composite
def saleae1_exports(draw: Any) -> bytes:
    rows = ["Time [s],Packet ID,MOSI,MISO"]
    for pid in range(draw(st.integers(0, 10))):
        if draw(st.integers(0, 20)) == 0:
            rows.append(draw(st.sampled_from(["", f"1,{pid} ,0x01,", "x,3,0x01,0x02", "1,,0x01,",
                                              f'1,"{pid}",0x01,0x02'])))
        for i, b in enumerate(draw(st.lists(st.integers(0, 255), min_size=1, max_size=20))):
            rows.append(f"{pid * 1e-3 + i * 8e-7:.9f},{pid},{_cell(draw, b)},"
                        f"{_cell(draw, draw(st.one_of(st.none(), st.integers(0, 255))))}")
    return ("\n".join(rows) + "\n").encode()


@settings(max_examples=50, deadline=None)
@given(saleae2_exports(), st.integers(min_value=5, max_value=3000))
def test_saleae2_reads_alike_in_any_chunks(data: bytes, chunk: int) -> None:
    fast, slow = _both(SALEAE2, data, SpiOptions(), chunk)
    assert fast == slow


@settings(max_examples=50, deadline=None)
@given(saleae1_exports(), st.integers(min_value=5, max_value=3000),
       st.sampled_from(["h2e", "e2h"]))
def test_saleae1_reads_alike_in_any_chunks(data: bytes, chunk: int, direction: str) -> None:
    fast, slow = _both(SALEAE1, data, SpiOptions(direction=direction), chunk)
    assert fast == slow


@pytest.mark.parametrize("read,head,row", [
    (read_saleae2, 'name,type,start_time,duration,"mosi","miso"\n"h2e","enable",0,0,,\n',
     '"h2e","result",0,0,0x01,0x02\n'),
    (read_saleae1, "Time [s],Packet ID,MOSI,MISO\n", "0.1,7,0x01,0x02\n"),
])
def test_saleae_transfer_without_chip_select_rising_is_bounded(read: Reader, head: str,
                                                                row: str) -> None:
    """A chip select that never rises: an error at the 4097th byte's line, whatever the
    chunking."""
    data = (head + row * 5000).encode()
    for chunk in (1 << 12, 1 << 20):
        with pytest.raises(InputError, match=r"line \d+: transfer longer than 4096"):
            list(read(io.BytesIO(data), SpiOptions(direction="h2e"), chunk_size=chunk))


def _sigrok_layout(text: str, joins: list[bool]) -> str:
    """Our one-change-per-line body rewritten as sigrok and PulseView write it: a ``#time``
    and its changes on one line, separated by spaces (where ``joins`` says so)."""
    head, body = text.split("$enddefinitions $end\n", 1)
    out: list[str] = []
    for i, line in enumerate(body.split("\n")):
        if out and not line.startswith(("#", "$")) and not out[-1].startswith("$") \
                and joins[i % len(joins)]:
            out[-1] += " " + line
        else:
            out.append(line)
    return head + "$enddefinitions $end\n" + "\n".join(out)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["h2e", "e2h"]), st.binary(max_size=40)),
                min_size=1, max_size=5),
       st.sampled_from([0, 1, 2, 3]), st.lists(st.booleans(), min_size=1, max_size=7),
       st.integers(min_value=7, max_value=3000))
def test_vcd_in_sigrok_layout_reads_back_alike_in_any_chunks(
        items: list[tuple[str, bytes]], mode: int, joins: list[bool], chunk: int) -> None:
    opts = SpiOptions(mode=mode)
    recs = [Transfer(i * 1e-4, d, payload) for i, (d, payload) in enumerate(items)]
    buf = io.StringIO()
    write_vcd(recs, buf, opts)
    raw = _sigrok_layout(buf.getvalue(), joins).encode()
    fast, slow = _both(VCD, raw, opts, chunk)
    assert fast == slow
    assert isinstance(fast, list)
    assert [r.data for r in fast] == [r.data for r in sorted(recs, key=lambda r: r.time or 0)]


@pytest.mark.parametrize("chunk", [64, 1 << 20])
def test_saleae2_iso8601_timestamps(chunk: int) -> None:
    """Logic 2's "Use ISO8601 timestamps" export: times since the epoch (UTC without a zone),
    in small chunks and whole."""
    rows = ['name,type,start_time,duration,"mosi","miso"']
    for i, stamp in enumerate(["2026-11-23T15:02:04.500000000+00:00",
                               "2026-11-23T16:02:04.5003+01:00", "2026-11-23T15:02:04.5006"]):
        rows.append(f'"h2e","enable",{stamp},2e-08,,')
        rows.append(f'"h2e","result",{stamp},8e-07,0x{i:02X},0xFF')
        rows.append(f'"h2e","disable",{stamp},2e-08,,')
    data = ("\n".join(rows) + "\n").encode()
    fast, slow = _both(SALEAE2, data, SpiOptions(), chunk)
    assert fast == slow
    assert isinstance(fast, list)
    base = 1795446124.5  # 2026-11-23T15:02:04.5Z
    assert [r.time for r in fast] == pytest.approx([base, base + 3e-4, base + 6e-4], abs=1e-6)
    assert [r.data for r in fast] == [b"\x00", b"\x01", b"\x02"]
    bad = data.replace(b"2026-11-23T15:02:04.5006", b"2026-13-23T15:02:04")
    with pytest.raises(InputError, match="line 8: bad time"):
        list(read_saleae2(io.BytesIO(bad), SpiOptions(), chunk_size=chunk))


@st.composite
def _mutated(draw: Any) -> tuple[str, bytes]:
    """A valid Saleae 2, Saleae 1 or VCD capture with a few bytes replaced, inserted or
    deleted (quotes, commas, CR, NUL, digits, separators...)."""
    fmt = draw(st.sampled_from(["saleae2", "saleae1", "vcd"]))
    if fmt == "saleae2":
        data = draw(saleae2_exports())
    elif fmt == "saleae1":
        data = draw(saleae1_exports())
    else:
        buf = io.StringIO()
        write_vcd([Transfer(i * 1e-4, d, p) for i, (d, p) in enumerate(
            draw(st.lists(st.tuples(st.sampled_from(["h2e", "e2h"]), st.binary(max_size=6)),
                          min_size=1, max_size=3)))], buf)
        data = buf.getvalue().encode()
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(out)))
        junk = draw(st.sampled_from([b'"', b",", b"\r", b"\x00", b"0", b"1", b"#", b" ", b"\n",
                                     b"\xff", b"x", b"0x1", b"#9" * 10, b""]))
        op = draw(st.sampled_from(["replace", "insert", "delete"]))
        if op == "insert":
            out[at:at] = junk
        elif op == "replace":
            out[at:at + len(junk)] = junk
        else:
            del out[at:at + draw(st.integers(1, 5))]
    return fmt, bytes(out)


@settings(max_examples=80, deadline=None)
@given(_mutated(), st.integers(min_value=5, max_value=2000))
def test_mutated_captures_read_alike_in_any_chunks(case: tuple[str, bytes], chunk: int) -> None:
    """Damaged captures: records or a typed error (``_both`` lets no other exception through),
    and the same records whatever the chunking when both reads take the file; a VCD gives the
    same error too. (In a CSV export, a quote left open makes the csv module read on across
    lines, so where a chunk ends can change which line the error names.)"""
    fmt, data = case
    opts = SpiOptions(direction="e2h")
    read = {"vcd": VCD, "saleae2": SALEAE2, "saleae1": SALEAE1}[fmt]
    small, whole = _both(read, data, opts, chunk)
    if fmt == "vcd" or (isinstance(small, list) and isinstance(whole, list)):
        assert small == whole
