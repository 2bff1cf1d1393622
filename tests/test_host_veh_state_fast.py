"""HOST_VEH_STATE_MSG: the template packer (``host/veh_state_fast.py``) against the dict path
(``veh_state_values`` + ``MessageCodec.encode_dasp``), byte for byte, with the same E2E state
afterwards; and where the packer declines, it changes nothing and the dict path decides."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eyeq_spi.catalog.messages import catalog, sw_release
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.errors import LocalProtocolError, SpecError
from eyeq_spi.host.host import HostEmulator
from eyeq_spi.host.scenario import ConstantDrive
from eyeq_spi.host.veh_state_fast import NAME, VehStatePacker
from eyeq_spi.twins import EXACT_ENV

_CODECS: dict[str, MessageCodec] = {}


def _codec(sw: str) -> MessageCodec:
    if sw not in _CODECS:
        _CODECS[sw] = MessageCodec(sw)
    return _CODECS[sw]


def _releases() -> list[str]:
    out = []
    for sw in catalog().sw_versions:
        try:
            _codec(sw).message(NAME)
        except SpecError:
            continue
        out.append(sw)
    return out


RELEASES = _releases()


def _reference(codec: MessageCodec, signals: dict[str, Any], now: float, rolling: int,
               counter: int, e2e: E2EState) -> Any:
    from eyeq_spi.host.scenario import veh_state_values

    msg = codec.message(NAME)
    try:
        values = veh_state_values(codec.layout(msg).zero_values(), signals, now,
                                  sw_release(codec.sw), rolling)
        return codec.encode_dasp(NAME, values, counter, e2e)
    except LocalProtocolError as exc:
        return f"LocalProtocolError: {exc}"
    except (OverflowError, ValueError, TypeError) as exc:
        return type(exc).__name__


def _fast(codec: MessageCodec, signals: dict[str, Any], now: float, rolling: int, counter: int,
          e2e: E2EState) -> Any:
    """The host's way: the packer, and the dict path where it declines."""
    before = (dict(e2e.sent), dict(e2e.seen))
    out = VehStatePacker(codec, sw_release(codec.sw)).encode(signals, now, rolling, counter, e2e)
    if out is None:
        assert (e2e.sent, e2e.seen) == before, "a declined message changed the E2E state"
        return _reference(codec, signals, now, rolling, counter, e2e)
    return out


def _members(sw: str) -> list[str]:
    lay = _codec(sw).layout(_codec(sw).message(NAME))
    return [f.name for f in lay.children["vehStateInfo"].fields]


_value = st.one_of(
    st.floats(allow_nan=False, width=32), st.floats(allow_infinity=True, allow_nan=True),
    st.integers(-5, 300), st.integers(-(1 << 65), 1 << 65), st.booleans(),
    st.sampled_from([0, 1, 0.5, "x", None]))


@st.composite
def _case(draw: st.DrawFn) -> tuple[str, dict[str, Any], float, int, int, int]:
    sw = draw(st.sampled_from(RELEASES))
    names = [*_members(sw), "notAMember", "SPI_Rolling_Count"]
    keys = draw(st.lists(st.sampled_from(names), max_size=6, unique=True))
    signals = {k: draw(_value) for k in keys}
    now = draw(st.one_of(st.floats(0, 1e5), st.sampled_from([-1.0, float("inf")])))
    return (sw, signals, now, draw(st.integers(0, 0xFFFF)), draw(st.integers(0, 255)),
            draw(st.integers(0, 3)))


@settings(max_examples=300, deadline=None)
@given(_case())
def test_packer_gives_the_dict_paths_bytes(case: tuple[str, dict[str, Any], float, int, int,
                                                         int]) -> None:
    sw, signals, now, rolling, counter, repeat = case
    codec = _codec(sw)
    ref_e2e, fast_e2e = E2EState(), E2EState()
    for k in range(repeat + 1):  # the rolling counters step on both sides alike
        want = _reference(codec, signals, now + k, rolling, counter, ref_e2e)
        got = _fast(codec, signals, now + k, rolling, counter, fast_e2e)
        assert got == want
    assert (fast_e2e.sent, fast_e2e.seen) == (ref_e2e.sent, ref_e2e.seen)


@pytest.mark.parametrize("sw", RELEASES)
def test_packer_takes_the_usual_drive_at_every_release(sw: str) -> None:
    """The constant drive (the demo's) is packed, not left to the dict path, and equals it."""
    codec = _codec(sw)
    packer = VehStatePacker(codec, sw_release(codec.sw))
    ref_e2e, fast_e2e = E2EState(), E2EState()
    signals = ConstantDrive(27.5, 0.01).signals(0.0)
    for k in range(300):  # past the 8-bit rolling counter's wrap
        now = 1.5 + k / 66.67
        got = packer.encode(signals, now, k & 0xFFFF, k & 0xFF, fast_e2e)
        assert got is not None
        assert got == _reference(codec, signals, now, k & 0xFFFF, k & 0xFF, ref_e2e)


def _host_wires(monkeypatch: pytest.MonkeyPatch, exact: str) -> list[bytes]:
    monkeypatch.setenv(EXACT_ENV, exact)
    host = HostEmulator(scenario=ConstantDrive(13.0, -0.2))
    sent: list[bytes] = []
    def send(message: bytes, now: float) -> int:
        sent.append(message)
        return 0

    host.conn.send = send  # type: ignore[method-assign]
    for k in range(70):
        host._send_veh_state(0.25 + k / 66.67)
    return sent


def test_host_sends_the_same_messages_on_both_paths(monkeypatch: pytest.MonkeyPatch) -> None:
    fast = _host_wires(monkeypatch, "0")
    assert fast == _host_wires(monkeypatch, "1")
    assert len(fast) == 70 and len(set(fast)) == 70
