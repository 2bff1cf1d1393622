"""The twin contract: every family's fast twin gives what its reference gives on the same
inputs, and ``EYEQ_SPI_EXACT=1`` makes every facade pick the reference.

One case per family (``eyeq_spi.twins.FAMILIES``); the inputs are the ones the families' own
tests use (the capture generators of ``test_codec_message_fast``, ``test_capture_pcapng_fast``,
``test_logic_saleae_fast``, the emulations of ``test_sim_dasp_fast``),
taken here at fixed seeds; those modules keep their randomised and fault-specific checks."""

from __future__ import annotations

import io
import math
import random
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi import twins
from eyeq_spi.capture.pcapng_io import Record, read_pcapng
from eyeq_spi.errors import InputError
from eyeq_spi.logic.options import SpiOptions

pytestmark = pytest.mark.twin

Pair = tuple[Any, Any]  # (reference's output, fast twin's output)


def _outcome(fn: Callable[[], Any]) -> Any:
    """The output, or the error's type and text (both paths must fail alike too)."""
    try:
        return fn()
    except InputError as exc:
        return f"{type(exc).__name__}: {exc}"


# -- logic ---------------------------------------------------------------------------------------
def _saleae2_export(seed: int) -> bytes:
    rng = random.Random(seed)
    rows = ['name,type,start_time,duration,"mosi","miso"']
    t = 0.0
    for _ in range(40):
        name = rng.choice(['"h2e"', '"e2h"', "h2e"])
        rows.append(f'{name},"enable",{t!r},2e-08,,')
        for _ in range(rng.randint(0, 20)):
            miso = "" if rng.random() < 0.2 else f"0x{rng.randrange(256):02X}"
            rows.append(f'{name},"result",{t + 1e-6:.9f},8e-07,0x{rng.randrange(256):02x},{miso}')
        if rng.random() < 0.9:
            rows.append(f'{name},"disable",{t + 1e-4!r},2e-08,,')
        t += 1e-3
    return ("\r\n".join(rows) + "\r\n").encode()


def _saleae1_export(seed: int) -> bytes:
    rng = random.Random(seed)
    rows = ["Time [s],Packet ID,MOSI,MISO"]
    for pid in range(30):
        for i in range(rng.randint(1, 20)):
            rows.append(f"{pid * 1e-3 + i * 8e-7:.9f},{pid},0x{rng.randrange(256):02X},"
                        f"{rng.randrange(256)}")
    return ("\n".join(rows) + "\n").encode()


def _saleae(kind: str) -> Pair:
    from eyeq_spi.logic import saleae_fast, saleae_ref

    data = _saleae2_export(1) if kind == "2" else _saleae1_export(2)
    out: list[list[Any]] = [[], []]
    for chunk in (7, 300, 1 << 20):
        for k, mod in enumerate((saleae_ref, saleae_fast)):
            read = getattr(mod, f"read_saleae{kind}")
            out[k].append(_outcome(lambda: list(read(io.BytesIO(data), SpiOptions(),  # noqa: B023
                                                     chunk_size=chunk))))  # noqa: B023
    assert len(out[0][0]) > 20
    return out[0], out[1]


def _vcd() -> Pair:
    from eyeq_spi.logic import vcd_fast, vcd_ref
    from eyeq_spi.logic.vcd_write import write_vcd
    from tests.test_logic_saleae_fast import _sigrok_layout

    rng = random.Random(3)
    out: list[list[Any]] = [[], []]
    for mode in range(4):
        opts = SpiOptions(mode=mode)
        recs = [Record(i * 1e-4, rng.choice(["h2e", "e2h"]), rng.randbytes(rng.randint(0, 40)))
                for i in range(30)]
        buf = io.StringIO()
        write_vcd(recs, buf, opts)
        for raw in (buf.getvalue().encode(),
                    _sigrok_layout(buf.getvalue(), [True, False, True]).encode()):
            for chunk in (7, 500, 1 << 20):
                for k, mod in enumerate((vcd_ref, vcd_fast)):
                    out[k].append(_outcome(lambda: list(mod.read_vcd(  # noqa: B023
                        io.BytesIO(raw), opts, chunk_size=chunk))))  # noqa: B023
    return out[0], out[1]


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
    from eyeq_spi.capture.pcapng_fast import chunks_from_records
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
            fast.append(list(batch.iter_records(chunks_from_records(recs, chunk))))
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
        fast.append((_outcome(lambda: [c.record(i) for c in pcapng_chunks(
            io.BytesIO(short), 1000, t_fast) for i in range(len(c))]), t_fast))  # noqa: B023
    return ref, fast


def _capture_write(tmp_path: Path) -> Pair:
    from tests.test_capture_pcapng_write_fast import _write

    rng = random.Random(6)
    recs = [(rng.choice(["h2e", "e2h"]), i * 2.5e-6, rng.randbytes(rng.choice([128, 128, 9])),
             rng.random() * 0.3) for i in range(800)]
    return (_write(tmp_path / "one.pcapng", False, recs, 97),
            _write(tmp_path / "blocks.pcapng", True, recs, 97))


# -- sim and runner ------------------------------------------------------------------------------
def _dasp() -> Pair:
    from tests.test_sim_dasp_fast import _dasp, _pair

    ref_sim, fast_sim = _pair(seed=5, objects=15, signs=20, light_spots=15)
    ref: list[bytes] = []
    fast: list[bytes] = []
    for k, t in enumerate((0.05, 0.4, 1.3)):
        for sim in (ref_sim, fast_sim):
            sim.scene.step(t, 12.0, 0.02)
        for m in _dasp(ref_sim):
            ref.append(ref_sim._dasp_bytes(m, k, t))
            fast.append(fast_sim._dasp_bytes(m, k, t))
    assert fast_sim.dasp_paths["packed"] == len(fast) and ref_sim.dasp_paths["packed"] == 0
    return ref, fast


def _veh_state() -> Pair:
    from eyeq_spi.codec.e2e import E2EState
    from tests.test_host_veh_state_fast import RELEASES, _codec, _fast, _reference

    rng = random.Random(7)
    ref: list[Any] = []
    fast: list[Any] = []
    for sw in RELEASES:
        e2e = (E2EState(), E2EState())
        for k in range(40):
            signals = {"vehicleVelocity": rng.uniform(0, 40), "vehicleYawRate": rng.random(),
                       "turnIndicator": rng.choice([0, 1, 2])}
            ref.append(_reference(_codec(sw), signals, k / 66.67, k, k, e2e[0]))
            fast.append(_fast(_codec(sw), signals, k / 66.67, k, k, e2e[1]))
    return ref, fast


CONTRACT: dict[str, Callable[[Path], Pair]] = {
    "logic.saleae (Logic 2)": lambda _: _saleae("2"),
    "logic.saleae (Logic 1.x)": lambda _: _saleae("1"),
    "logic.vcd": lambda _: _vcd(),
    "codec.layout": lambda _: _layout(),
    "dissect.engine + codec.message": lambda _: _dissect(),
    "capture.pcapng": _pcapng,
    "capture.write": _capture_write,
    "sim.dasp": lambda _: _dasp(),
    "host.veh_state": lambda _: _veh_state(),
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
class FastTwinUsedError(Exception):
    pass


def _poison(*_: Any, **__: Any) -> Any:
    raise FastTwinUsedError


def _through_facades(tmp_path: Path) -> dict[str, tuple[list[tuple[Any, str, Any]],
                                                      Callable[[], Any]]]:
    """Per family: where to poison its fast twin (it then raises), and a run through the code
    the rest of the project calls (facade, config default, runner default)."""
    from eyeq_spi.capture import pcapng_fast, pcapng_write_fast
    from eyeq_spi.capture.pcapng_io import CaptureWriter
    from eyeq_spi.codec.layout_fast import FastCodec
    from eyeq_spi.codec.message import MessageCodec
    from eyeq_spi.dissect import engine_fast_messages, pipeline_fast
    from eyeq_spi.dissect.pipeline import SMALL_INPUT, dissect_files
    from eyeq_spi.host import veh_state_fast
    from eyeq_spi.host.host import HostEmulator
    from eyeq_spi.logic import saleae, saleae_fast, vcd, vcd_fast
    from eyeq_spi.logic.vcd_write import write_vcd
    from eyeq_spi.sim import dasp_fast
    from eyeq_spi.sim.config import SimConfig
    from eyeq_spi.sim.eyeq import SimulatedEyeQ
    from tests.test_codec_message_fast import _capture

    buf = io.StringIO()
    write_vcd([Record(0.0, "h2e", b"\x01\x02")], buf, SpiOptions())
    vcd_bytes = buf.getvalue().encode()
    pcap = tmp_path / "c.pcapng"
    records = _capture([])
    with CaptureWriter(pcap) as w:
        span = 0.0
        while pcap.stat().st_size < SMALL_INPUT:  # big enough for the pipeline's fast path
            for r in records:
                assert r.direction is not None and r.time is not None
                w.write(r.direction, span + r.time, r.data)
            span += (records[-1].time or 0.0) + 1.0
            w.flush()
    codec = MessageCodec()

    def dasp_layout() -> Any:
        m = next(m for m in codec.cat.messages if m.protocol == "DASP" and m.exists_in(codec.sw))
        lay = codec.layout(m)
        return [lay.parse(lay.build(lay.zero_values()))]

    def batch() -> Any:
        return list(dissect_files([str(pcap)]))

    def dasp() -> Any:
        sim = SimulatedEyeQ(SimConfig())
        sim.warm_up()
        m = next(m for m in sim.codec.cat.messages
                 if m.protocol == "DASP" and m.direction == "e2h" and m.exists_in(sim.sw))
        return [sim._dasp_bytes(m, 0, 0.1)]

    def capture() -> Any:
        with CaptureWriter(tmp_path / "w.pcapng", idle_flush=False) as w:
            for i in range(3):
                w.write("h2e", i * 1e-3, bytes(128))
        return (tmp_path / "w.pcapng").read_bytes()

    def veh_state() -> Any:
        host = HostEmulator()
        sent: list[bytes] = []
        def send(message: bytes, now: float) -> int:
            sent.append(message)
            return 0

        host.conn.send = send  # type: ignore[method-assign]
        host._send_veh_state(0.5)
        return sent

    return {
        "logic.saleae": ([(saleae_fast, "saleae2_chunk", _poison)], lambda: list(
            saleae.read_saleae2(io.BytesIO(_saleae2_export(1)), SpiOptions()))),
        "logic.vcd": ([(vcd_fast.FastPath, "build", classmethod(_poison))],
                      lambda: list(vcd.read_vcd(io.BytesIO(vcd_bytes), SpiOptions()))),
        "codec.layout": ([(FastCodec, "decode", _poison), (FastCodec, "encode", _poison)],
                         dasp_layout),
        "codec.message": ([(engine_fast_messages, "vec_layout", _poison)], batch),
        "dissect.engine": ([(pipeline_fast, "ChunkFeeder", _poison)], batch),
        "capture.pcapng": ([(pipeline_fast, "pcapng_chunks", _poison),
                            (pcapng_fast, "pcapng_chunks", _poison)], batch),
        "capture.write": ([(pcapng_write_fast, "encode_blocks", _poison)], capture),
        "sim.dasp": ([(dasp_fast.DaspPacker, "build", classmethod(_poison))], dasp),
        "host.veh_state": ([(veh_state_fast.VehStatePacker, "encode", _poison)], veh_state),
    }


@pytest.mark.parametrize("family", list(twins.FAMILIES))
def test_exact_switch_selects_every_reference(family: str, tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    poisons, run = _through_facades(tmp_path)[family]
    for obj, name, value in poisons:
        monkeypatch.setattr(obj, name, value)
    monkeypatch.setenv(twins.EXACT_ENV, "0")
    with pytest.raises(FastTwinUsedError):  # the poison is on the path the facade takes by default
        run()
    monkeypatch.setenv(twins.EXACT_ENV, "1")
    run()


def test_logic_references_do_not_import_their_fast_twins() -> None:
    """The Saleae and VCD references read a file without numpy or their fast twins loaded."""
    import subprocess
    import sys

    code = (
        "import io, sys\n"
        "from eyeq_spi.logic import saleae_ref, vcd_ref\n"
        "from eyeq_spi.logic.options import SpiOptions\n"
        "data = b'Time [s],Packet ID,MOSI,MISO\\n0.1,1,0x01,0x02\\n'\n"
        "assert list(saleae_ref.read_saleae1(io.BytesIO(data), SpiOptions()))\n"
        "print(sorted(m for m in sys.modules if m == 'numpy' or m.endswith('_fast')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True)
    assert out.stdout.strip() == "[]"
