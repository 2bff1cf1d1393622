from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eyeq_spi.crc import VARIANTS
from eyeq_spi.errors import LocalProtocolError, RemoteProtocolError
from eyeq_spi.link.frame import FRAME_SIZE, BitOrder, Frame, FrameCodec, FrameKind, NakReason

codec = FrameCodec()
nibble = st.integers(0, 15)
twelve = st.integers(0, 4095)


@given(d=nibble, r=nibble, rsp=twelve, num=twelve, data=st.binary(min_size=122, max_size=122),
       order=st.sampled_from(list(BitOrder)))
def test_any_header_round_trips(d: int, r: int, rsp: int, num: int, data: bytes,
                                order: BitOrder) -> None:
    c = FrameCodec(bit_order=order)
    wire = c.encode(Frame(d, r, rsp, num, data))
    assert len(wire) == FRAME_SIZE
    f = c.decode(wire)
    assert (f.d, f.r, f.rsp, f.num) == (d, r, rsp, num)
    assert c.crc_ok(wire, f)
    if d not in (FrameKind.ACK, FrameKind.NAK):
        assert f.data == data
    assert c.encode(f) == wire


def test_header_word_is_lsb_first_little_endian() -> None:
    # L1: D in bits 0-3, so a DATA frame with R = 0 starts with byte 0x08.
    wire = codec.data_frame(rsp=0x123, num=0xABC, data=b"\x00\x01z")
    word = int.from_bytes(wire[:4], "little")
    assert wire[0] == 0x08
    assert word == 0x8 | (0 << 4) | (0x123 << 8) | (0xABC << 20)
    assert wire[6:9] == b"\x00\x01z" and wire[9:] == bytes(119)  # zero padding


def test_msb_first_order_is_configurable() -> None:
    c = FrameCodec(bit_order="msb_first")
    word = int.from_bytes(c.data_frame(0, 1, b"")[:4], "little")
    assert word >> 28 == 0x8 and word & 0xFFF == 1


def test_crc_covers_header_and_data_of_a_data_frame() -> None:
    wire = codec.data_frame(0, 5, b"abc")
    crc = int.from_bytes(wire[4:6], "little")
    from eyeq_spi.crc import crc16
    assert crc == crc16(wire[:4] + wire[6:])


def test_ack_and_nak_crc_cover_the_header_only() -> None:
    from eyeq_spi.crc import crc16
    ack = codec.ack(77)
    nak = codec.nak(78, NakReason.CRC_MISMATCH)
    for wire in (ack, nak):
        assert int.from_bytes(wire[4:6], "little") == crc16(wire[:4])
        assert wire[6:] == bytes(122)
        padded = wire[:6] + b"\xff" * 122  # a receiver ignores ACK/NAK pad bytes (L3)
        f = codec.decode(padded)
        assert codec.crc_ok(padded, f)
    a, n = codec.decode(ack), codec.decode(nak)
    assert (a.kind, a.rsp, a.num) == (FrameKind.ACK, 77, 0)
    assert (n.kind, n.rsp, n.num) == (FrameKind.NAK, 78, 0x002)


@pytest.mark.parametrize("length", [0, 1, 127, 129, 256])
def test_wrong_length_is_a_frame_error(length: int) -> None:
    with pytest.raises(RemoteProtocolError):
        codec.decode(bytes(length))


def test_building_out_of_range_fields_is_refused() -> None:
    with pytest.raises(LocalProtocolError):
        Frame(0x8, 0, 4096, 0)
    with pytest.raises(LocalProtocolError):
        codec.data_frame(0, 0, bytes(123))


def test_other_crc_variant_is_configurable() -> None:
    c = FrameCodec(crc=VARIANTS["CRC-16/KERMIT"])
    wire = c.data_frame(0, 1, b"x")
    assert c.crc_ok(wire, c.decode(wire))
    assert not codec.crc_ok(wire, codec.decode(wire))


@given(st.integers(0, 15), st.integers(0, 15), st.integers(0, 4095), st.integers(0, 4095),
       st.binary(min_size=122, max_size=122))
def test_hot_path_codec_agrees_with_the_construct_reference(d: int, r: int, rsp: int, num: int,
                                                            data: bytes) -> None:
    from eyeq_spi.link.frame import FRAME_LAYOUT, Frame, FrameCodec

    fc = FrameCodec()
    word = fc.pack_header(d, r, rsp, num)
    crc = fc.compute_crc(d, word.to_bytes(4, "little"), data)
    ref = bytes(FRAME_LAYOUT.build({"header": word, "crc": crc, "data": data}))
    wire = fc.encode(Frame(d, r, rsp, num, data))
    if d not in (4, 2):
        assert wire == ref
    parsed = FRAME_LAYOUT.parse(ref)
    got = fc.decode(ref)
    assert (got.crc, got.data) == (parsed.crc, parsed.data)
    assert fc.unpack_header(parsed.header) == (got.d, got.r, got.rsp, got.num)


@given(st.binary(min_size=FRAME_SIZE, max_size=FRAME_SIZE), st.sampled_from(list(BitOrder)),
       st.booleans())
def test_judge_agrees_with_decode_and_crc_ok(raw: bytes, order: BitOrder, fix_crc: bool) -> None:
    """The receiver's hot path (FrameCodec.judge) reads what decode + crc_ok read, for any 128
    bytes: random headers (every D, valid or not) with a good or a random CRC."""
    codec = FrameCodec(bit_order=order)
    if fix_crc:
        d = codec.unpack_header(int.from_bytes(raw[:4], "little"))[0]
        crc = codec.compute_crc(d, raw[:4], raw[6:])
        raw = raw[:4] + crc.to_bytes(2, "little") + raw[6:]
    frame = codec.decode(raw)
    assert codec.check(raw) == (frame.d, frame.r, frame.rsp, frame.num, codec.crc_ok(raw, frame))
    if fix_crc:
        assert codec.check(raw)[4]


@pytest.mark.parametrize("length", [0, 127, 129])
def test_judge_refuses_a_wrong_length(length: int) -> None:
    with pytest.raises(RemoteProtocolError):
        FrameCodec().check(bytes(length))


@given(st.integers(0, 4095), st.integers(0, 4095), st.binary(max_size=122),
       st.sampled_from(list(BitOrder)), st.sampled_from(["CRC-16/CCITT-FALSE", "CRC-16/KERMIT"]))
def test_data_frame_is_encode_of_a_data_frame(rsp: int, num: int, data: bytes, order: BitOrder,
                                              crc: str) -> None:
    """The sender's hot path (FrameCodec.data_frame, no Frame built) gives encode's bytes."""
    c = FrameCodec(bit_order=order, crc=VARIANTS[crc])
    assert c.data_frame(rsp, num, data) == c.encode(
        Frame(FrameKind.DATA, 0, rsp, num, data.ljust(122, b"\0")))
