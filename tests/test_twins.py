"""The twin contract: every family's fast twin gives what its reference gives on the same
inputs, and ``EYEQ_SPI_EXACT=1`` makes every facade pick the reference.

One case per family (``eyeq_spi.twins.FAMILIES``); the inputs are the ones the families' own
tests use (the capture generators of ``test_codec_message_fast``, ``test_capture_pcapng_fast``,
the emulations of ``test_sim_dasp_fast``), taken here at fixed seeds; those modules keep their
randomised and fault-specific checks."""

from __future__ import annotations

import io
import json
import math
import os
import random
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi import twins
from eyeq_spi.capture.pcapng_io import read_pcapng
from eyeq_spi.errors import InputError

pytestmark = pytest.mark.twin

Pair = tuple[Any, Any]  # (reference's output, fast twin's output)


def _outcome(fn: Callable[[], Any]) -> Any:
    """The output, or the error's type and text (both paths must fail alike too)."""
    try:
        return fn()
    except InputError as exc:
        return f"{type(exc).__name__}: {exc}"


# -- codec ---------------------------------------------------------------------------------------
def _same(a: Any, b: Any) -> bool:
    """Equal, NaN equal to NaN (random bytes decode to NaNs)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a):
        return math.isnan(b)
    return bool(a == b) and type(a) is type(b)


def _layout() -> Pair:
    from tests.test_codec_message_fast import CASES, _codec

    rng = random.Random(4)
    ref: list[Any] = []
    fast: list[Any] = []
    for name, sw in CASES:
        lay = _codec(sw).layout(_codec(sw).message(name))
        zeros = lay.zero_values()
        ref.append(lay.build_construct(zeros))
        fast.append(lay.fast.encode(zeros))
        for _ in range(3):
            data = rng.randbytes(lay.size)
            a, b = lay.parse_construct(data), lay.fast.decode(data)
            ref.append(True)
            fast.append(_same(a, b) or (name, sw, data.hex()))
    return ref, fast


def _dissect() -> Pair:
    """The exact dissector against the batch one (frames, spans, the vectorised message decode
    of ``codec.message_fast``), clean and under application faults, chunked finely and not."""
    from eyeq_spi.capture.pcapng_fast import chunks_from_transfers
    from eyeq_spi.dissect import engine
    from eyeq_spi.dissect import engine_fast as batch
    from tests.test_codec_message_fast import _capture

    ref: list[Any] = []
    fast: list[Any] = []
    for faults in ([], [(3, 2), (10, 5), (25, 7)]):
        recs = _capture(faults)
        want = list(engine.iter_records(recs))
        for chunk in (7, 1 << 15):
            ref.append(want)
            fast.append(list(batch.iter_records(chunks_from_transfers(recs, chunk))))
    assert len(ref[0]) > 40
    return ref, fast


def _pcapng(tmp_path: Path) -> Pair:
    from eyeq_spi.capture.pcapng_fast import pcapng_chunks
    from eyeq_spi.capture.pcapng_io import Tail
    from tests.test_capture_pcapng_fast import _capture

    blob = _capture(tmp_path / "c.pcapng")
    ref: list[Any] = []
    fast: list[Any] = []
    for cut in (None, 1000, 160 * 700 + 13):
        short = blob if cut is None else blob[:cut]
        t_ref, t_fast = Tail(), Tail()
        ref.append((_outcome(lambda: list(read_pcapng(io.BytesIO(short), t_ref))),  # noqa: B023
                    t_ref))
        fast.append((_outcome(lambda: [c.transfer(i) for c in pcapng_chunks(
            io.BytesIO(short), 1000, t_fast) for i in range(len(c))]), t_fast))  # noqa: B023
    return ref, fast


# -- sim and runner ------------------------------------------------------------------------------
def _dasp() -> Pair:
    from tests.test_sim_dasp_fast import Twins

    twins = Twins(None, seed=5, objects=15, signs=20, light_spots=15)
    ref: list[bytes] = []
    fast: list[bytes] = []
    for k, t in enumerate((0.05, 0.4, 1.3)):
        twins.step(t, 12.0, 0.02)
        ref_now, fast_now = twins.messages_at(t, k)
        ref += ref_now
        fast += fast_now
    return ref, fast


CONTRACT: dict[str, Callable[[Path], Pair]] = {
    "codec.layout": lambda _: _layout(),
    "dissect.engine + codec.message": lambda _: _dissect(),
    "capture.pcapng": _pcapng,
    "sim.dasp": lambda _: _dasp(),
}


def test_every_family_has_a_contract_case() -> None:
    named = {k.split(" ")[0] for k in CONTRACT} | {"codec.message"}
    assert named == set(twins.FAMILIES)


@pytest.mark.parametrize("family", list(CONTRACT))
def test_fast_twin_gives_what_the_reference_gives(family: str, tmp_path: Path) -> None:
    ref, fast = CONTRACT[family](tmp_path)
    assert ref, "no output: the case compared nothing"
    assert fast == ref


# -- the switch ----------------------------------------------------------------------------------
@pytest.mark.parametrize("exact", ["0", "1"])
def test_exact_switch_runs_dissect_on_the_references(exact: str, tmp_path: Path) -> None:
    """``EYEQ_SPI_EXACT=1``: ``dissect`` of a capture big enough for the fast path reads it
    without loading a fast leaf (nor numpy); unset, it loads them. Same output either way."""
    import subprocess
    import sys

    from eyeq_spi.capture.pcapng_io import CaptureWriter
    from tests.test_codec_message_fast import _capture

    pcap = tmp_path / "c.pcapng"
    records = _capture([])
    with CaptureWriter(pcap, idle_flush=False) as w:
        for k in range(40):  # about 300 KiB: over the fast path's threshold
            for r in records:
                assert r.direction is not None and r.time is not None
                w.write(r.direction, k * 10.0 + r.time, r.data)
    code = ("import sys\n"
            "from eyeq_spi.dissect.pipeline import dissect_files\n"
            f"n = sum(1 for _ in dissect_files([{str(pcap)!r}]))\n"
            "import json\n"
            "print(json.dumps([n, [m.rsplit('.', 1)[1] for m in sys.modules\n"
            "                      if m.startswith('eyeq_spi.') and m.endswith('_fast')]]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True, env={**os.environ, twins.EXACT_ENV: exact})
    count, loaded = json.loads(out.stdout)
    assert count > 1000
    fast = {"engine_fast", "pcapng_fast", "pipeline_fast", "message_fast"}
    assert fast & set(loaded) == (set() if exact == "1" else fast)


@pytest.mark.parametrize("exact", ["0", "1"])
def test_exact_switch_runs_the_layouts_on_construct(exact: str) -> None:
    """``EYEQ_SPI_EXACT=1``: a layout encodes and decodes through construct (the reference),
    which the generated ``struct`` codec never imports; the values are the same."""
    import subprocess
    import sys

    code = ("import json, sys\n"
            "from eyeq_spi.codec.message import MessageCodec\n"
            "c = MessageCodec()\n"
            "m = next(m for m in c.cat.messages if m.protocol == 'DASP' and m.exists_in(c.sw))\n"
            "lay = c.layout(m)\n"
            "values = lay.parse(lay.build(lay.zero_values()))\n"
            "print(json.dumps([values == lay.zero_values(), 'construct' in sys.modules]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True, env={**os.environ, twins.EXACT_ENV: exact})
    assert json.loads(out.stdout) == [True, exact == "1"]
