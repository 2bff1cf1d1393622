"""MESP parameters (M3) parsed without construct: the same values and the same error text as
the construct Struct the encoders use (``codec.mesp.param_types``), for every parameter list of
``specs/mesp.yaml`` and for made-up ones, on good, short, long and non-ASCII bodies."""

from __future__ import annotations

from typing import Any

import pytest
from construct import Struct, Terminated
from hypothesis import given, settings
from hypothesis import strategies as st

from eyeq_spi.catalog.messages import MespParam, catalog
from eyeq_spi.codec.mesp import MalformedParamsError, MespCodec, param_types, parse_params

TYPES = ("u8", "u16", "u32", "string", "bytes")


def _reference(params: tuple[MespParam, ...], body: bytes) -> tuple[str, Any]:
    types = param_types()
    s = Struct(*(p.name / types[p.type] for p in params), Terminated)
    try:
        c = s.parse(body)
    except Exception as exc:  # construct's errors: the first line is what a record shows
        return "error", str(exc).splitlines()[0]
    return "ok", {k: v for k, v in c.items() if not k.startswith("_")}


def _ours(params: tuple[MespParam, ...], body: bytes) -> tuple[str, Any]:
    try:
        return "ok", parse_params(params, body)
    except MalformedParamsError as exc:
        return "error", str(exc)


_params = st.lists(st.sampled_from(TYPES), max_size=5).map(
    lambda ts: tuple(MespParam(f"p{i}", t) for i, t in enumerate(ts)))


def _body(params: tuple[MespParam, ...], data: st.DataObject) -> bytes:
    """A body near the layout: each parameter well formed or cut, sometimes bytes appended."""
    out = b""
    for p in params:
        if p.type in ("string", "bytes"):
            raw = data.draw(st.binary(max_size=6))
            length = data.draw(st.sampled_from([len(raw), len(raw) + 1, len(raw) - 1]))
            out += max(length, 0).to_bytes(4, "little") + raw
        else:
            out += data.draw(st.binary(min_size={"u8": 1, "u16": 2, "u32": 4}[p.type],
                                       max_size={"u8": 1, "u16": 2, "u32": 4}[p.type]))
    cut = data.draw(st.integers(0, len(out)))
    return data.draw(st.sampled_from([out, out[:cut], out + data.draw(st.binary(max_size=3))]))


@settings(max_examples=400, deadline=None)
@given(_params, st.data())
def test_parse_params_agrees_with_construct(params: tuple[MespParam, ...],
                                            data: st.DataObject) -> None:
    body = _body(params, data)
    assert _ours(params, body) == _reference(params, body)


@pytest.mark.parametrize("f", catalog().mesp, ids=lambda f: f.name)
@settings(max_examples=30, deadline=None)
@given(data=st.data())
def test_every_spec_function_parses_as_construct_does(f: Any, data: st.DataObject) -> None:
    for params in (f.request, f.reply):
        body = _body(params, data)
        assert _ours(params, body) == _reference(params, body)


def test_a_non_ascii_string_and_a_short_body_read_as_construct_says() -> None:
    params = (MespParam("a", "u16"), MespParam("b", "string"))
    assert _ours(params, b"\x01\x00\x02\x00\x00\x00a\xff") == (
        "error", "cannot use encoding 'ascii' to decode b'a\\xff'")
    assert _ours(params, b"\x01") == ("error", "Error in path (parsing) -> a")
    assert _ours(params, b"\x01\x00\x00\x00\x00\x00!") == ("error", "Error in path (parsing)")


def test_encode_then_decode_round_trips_without_construct_on_the_decode_side() -> None:
    codec = MespCodec(catalog())
    f = next(f for f in catalog().mesp if f.request)
    values = {p.name: ("x" if p.type == "string" else b"y" if p.type == "bytes" else 1)
              for p in f.request}
    data = codec.encode_request(f.name, 3, values)
    out = codec.decode(data)
    assert not out.errors and out.name == f.name and out.fields == values
