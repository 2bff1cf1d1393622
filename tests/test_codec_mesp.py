"""MESP parameters (M3) encoded and decoded by one codec built from ``specs/mesp.yaml``: every
function's request and reply round-trip, and a malformed parameter block is a record's error
(naming what is wrong), never an exception."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eyeq_spi.catalog.messages import MespFunction, MespParam, catalog
from eyeq_spi.codec.mesp import REPLY_BIT, MespCodec

CODEC = MespCodec(catalog())
VALUES = {"u8": st.integers(0, 0xFF), "u16": st.integers(0, 0xFFFF),
          "u32": st.integers(0, 0xFFFF_FFFF),
          "string": st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=12),
          "bytes": st.binary(max_size=12)}


def _values(params: tuple[MespParam, ...], data: st.DataObject) -> dict[str, Any]:
    return {p.name: data.draw(VALUES[p.type]) for p in params}


@pytest.mark.parametrize("f", catalog().mesp, ids=lambda f: f.name)
@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_every_spec_function_round_trips(f: MespFunction, data: st.DataObject) -> None:
    request = _values(f.request, data)
    out = CODEC.decode(CODEC.encode_request(f.name, 5, request))
    assert (out.errors, out.name, out.fields) == ([], f.name, request)
    assert out.header["counter"] == 5 and not out.header["reply"]
    reply = _values(f.reply, data)
    out = CODEC.decode(CODEC.encode_reply(f.name, 5, 0, reply))
    assert (out.errors, out.fields) == ([], {"ret": 0, **reply})
    assert out.header["tag"] == REPLY_BIT | 5


@pytest.mark.parametrize("f", [f for f in catalog().mesp if f.request], ids=lambda f: f.name)
@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_a_cut_or_padded_body_is_an_error_not_an_exception(f: MespFunction,
                                                         data: st.DataObject) -> None:
    whole = CODEC.encode_request(f.name, 1, _values(f.request, data))
    cut = data.draw(st.integers(5, len(whole) - 1))
    for broken in (whole[:cut], whole + data.draw(st.binary(min_size=1, max_size=3))):
        out = CODEC.decode(broken)
        assert out.name == f.name and len(out.errors) == 1
        assert out.errors[0].startswith(f"{f.name}: malformed parameters: ")


def _one_function(params: tuple[MespParam, ...]) -> MespCodec:
    codec = MespCodec(catalog())
    f = MespFunction("TEST_FN", 0x7F, 0x01, params, ())
    codec.functions = {(f.service, f.function): f}
    return codec


def test_a_malformed_block_names_what_is_wrong() -> None:
    codec = _one_function((MespParam("a", "u16"), MespParam("b", "string")))
    head = bytes((0x7F, 0x5E, 0x7F, 0x01, 0x00))
    assert codec.decode(head + b"\x01\x00\x02\x00\x00\x00a\xff").errors == [
        "TEST_FN: malformed parameters: cannot use encoding 'ascii' to decode b'a\\xff'"]
    assert codec.decode(head + b"\x01").errors == [
        "TEST_FN: malformed parameters: Error in path (parsing) -> a"]
    assert codec.decode(head + b"\x01\x00\x00\x00\x00\x00!").errors == [
        "TEST_FN: malformed parameters: Error in path (parsing)"]
    assert codec.decode(head + b"\x01\x00\x01\x00\x00\x00z").fields == {"a": 1, "b": "z"}


def test_a_failed_reply_carries_only_its_ret() -> None:
    f = next(f for f in catalog().mesp if f.reply)
    out = CODEC.decode(CODEC.encode_reply(f.name, 2, 3, {}))
    assert (out.errors, out.fields) == ([], {"ret": 3})
