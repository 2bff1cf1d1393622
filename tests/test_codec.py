"""Codecs built from specs/: round trips of every struct/message/variant, seed vectors, E2E."""

from __future__ import annotations

import struct
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eyeq_spi.catalog.messages import catalog
from eyeq_spi.codec.bits import BitSignalCodec
from eyeq_spi.codec.e2e import E2EState, protect, verify
from eyeq_spi.codec.intrinsic import (
    default_eeprom_image,
    eeprom_crc_ok,
    intrinsic_params_from_eeprom,
    normalise_num_distor_params,
    version_bytes,
    version_text,
)
from eyeq_spi.codec.layout import LayoutCache
from eyeq_spi.codec.message import MessageCodec, classify
from eyeq_spi.errors import LocalProtocolError
from tests.strategies import layout_values, signal_value

pytestmark = pytest.mark.twin  # runs a reference/fast twin: also run with EYEQ_SPI_EXACT=1

CAT = catalog()
LC = LayoutCache(CAT)
STRUCT_VARIANTS = [(n, k) for n, s in CAT.structs.items() for k in s.variants]
EDR_LB1 = bytes.fromhex("065E0601020601040101000000" "01")


@pytest.mark.parametrize(("name", "variant"), STRUCT_VARIANTS)
def test_every_struct_variant_round_trips(name: str, variant: str) -> None:
    lay = LC.get(name, variant)

    @settings(max_examples=6 if lay.size > 400 else 15, deadline=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                     HealthCheck.large_base_example])
    @given(layout_values(CAT, lay))
    def check(values: dict[str, Any]) -> None:
        wire = lay.build(values)
        assert len(wire) == lay.size
        assert lay.parse(wire) == values
        assert lay.build(lay.parse(wire)) == wire
        # the generated fast path and the construct reference agree, both ways
        assert lay.build_construct(values) == wire
        assert lay.parse_construct(wire) == values

    check()


_EXAMPLES: dict[tuple[str, str], dict[str, Any]] = {}


def _signature(lay: Any) -> str:
    inner = ",".join(_signature(c) for c in lay.children.values())
    return f"{lay.name}:{lay.variant}({inner})"


def _example(name: str, sw: str) -> dict[str, Any]:
    """One generated value per layout variant (layouts repeat across releases)."""
    lay = LC.get(name, sw)
    key = (name, _signature(lay))
    if key not in _EXAMPLES:
        _EXAMPLES[key] = layout_values(CAT, lay).example()
    return _EXAMPLES[key]


@pytest.mark.parametrize("sw", list(CAT.sw_versions))
def test_every_message_round_trips_with_e2e_at_every_release(sw: str) -> None:
    codec = MessageCodec(sw)
    for msg in CAT.messages:
        if not msg.exists_in(sw) or msg.protocol != "DASP":
            continue
        lay = codec.layout(msg)
        values = _example(msg.payload, sw)
        e2e_tx, e2e_rx = E2EState(), E2EState()
        for counter in (0, 1):
            wire = codec.encode_dasp(msg.name, values, counter=counter, e2e=e2e_tx)
            assert len(wire) == 4 + lay.size
            out = codec.decode(wire, e2e_rx)
            assert out.protocol == "DASP" and out.name == msg.name, out.errors
            assert out.errors == [], out.errors
            assert out.header == {"data_id": msg.data_id, "counter": counter}


def test_unused_bitfield_bits_are_sent_as_ones() -> None:
    lay = LC.get("eyeq_video_diagnostics_t", "sw5")
    values = layout_values(CAT, lay).example()
    for f in lay.fields:
        if f.bits:
            values[f.name] = 0
    wire = lay.build(values)
    # bits 5 and 6 are RESERVED members in SW5; the container is fully used, so all zero
    assert wire[-1] == 0x00
    lay2 = LC.get("eyeq_vision_failsafes_t", "sw6")
    v2 = layout_values(CAT, lay2).example()
    v2["outOfCalibTSR"] = 0
    f = lay2.field("outOfCalibTSR")
    assert lay2.build(v2)[f.offset] == 0b1100_0000  # bits 6-7 unused -> 1 (D2)


def test_bitfield_value_that_does_not_fit_is_a_codec_error() -> None:
    lay = LC.get("eyeq_vision_failsafes_t", "sw6")
    v = layout_values(CAT, lay).example()
    v["outOfCalibTSR"] = 64
    with pytest.raises(LocalProtocolError, match="outOfCalibTSR"):
        lay.build(v)


# -- seed vectors ------------------------------------------------------------------------------
def test_edr_example_both_ways() -> None:
    codec = MessageCodec()
    wire = codec.mesp.encode_request(
        "SendParamsToCalibrationTool", 2,
        {"edr_type": 6, "edr_policy": 1, "edr_function": 4, "edr_params_num": 1,
         "params": b"\x01"},
    )
    assert wire == EDR_LB1
    out = codec.decode(EDR_LB1)
    assert (out.protocol, out.name, out.errors) == ("MESP", "SendParamsToCalibrationTool", [])
    assert out.header == {"service": 6, "function": 1, "tag": 2, "counter": 2, "reply": False}
    assert out.fields == {"edr_type": 6, "edr_policy": 1, "edr_function": 4,
                          "edr_params_num": 1, "params": b"\x01"}


def test_appendix_e_eeprom_example() -> None:
    ee = BitSignalCodec.for_message("EEPROM_DATA")
    assert ee.to_raw(ee.signals["CCAM_camK1_FocalLengthX_m"], 1502.6) == 24041
    assert ee.to_raw(ee.signals["CCAM_K4_PrincipalPointX_m"], 919.4) == 14710
    # distorParams are written as IEEE binary32; the seed's hex column keeps 7 digits
    listed = {0: (-0.000762153, "BA47CB3"), 1: (0.000774594, "3A4B0E2"),
              2: (-0.001215783, "BA9F5AE"), 10: (-0.001103006, "BA9092B")}
    image = default_eeprom_image()
    values = ee.decode(image[: ee.length])
    for i, (value, hexprefix) in listed.items():
        sig = ee.signals[f"CCAM_distorParams_m_{i}"]
        assert f"{ee.to_raw(sig, value):08X}".startswith(hexprefix)
        assert values[sig.name] == pytest.approx(value, rel=1e-6)
    assert values["CCAM_camK1_FocalLengthX_m"] == 24041 * 0.0625
    assert eeprom_crc_ok(image)
    broken = bytearray(image)
    broken[3] ^= 0x10
    assert not eeprom_crc_ok(bytes(broken))


def test_boot_version_example() -> None:
    assert version_bytes("7.1.23") == bytes.fromhex("07011700")
    assert version_text(bytes.fromhex("07011700")) == "7.1.23"
    with pytest.raises(LocalProtocolError):
        version_bytes("7.1.300")


@pytest.mark.parametrize(("raw", "sent"), [(3, 7), (7, 7), (11, 15), (15, 15)])
def test_num_of_distor_params_is_normalised(raw: int, sent: int) -> None:
    assert normalise_num_distor_params(raw) == sent


def test_num_of_distor_params_other_values_are_refused() -> None:
    with pytest.raises(LocalProtocolError):
        normalise_num_distor_params(5)


def test_intrinsic_params_from_eeprom_feed_message_0x84() -> None:
    params = intrinsic_params_from_eeprom(default_eeprom_image())
    assert params["CCAM_Num_Of_distorParams_m"] == 15  # Appendix E example has 11
    msg = BitSignalCodec.for_message("Init_Intrinsic_Calibration")
    decoded = msg.decode(msg.encode(params))
    assert decoded["CCAM_camK1_FocalLengthX_m"] == 24041 * 0.0625


# -- init messages -----------------------------------------------------------------------------
INIT_VARIANTS = [(n, k) for n, m in CAT.init_messages.items() for k in m.variants]


@pytest.mark.parametrize(("name", "variant"), INIT_VARIANTS)
def test_every_init_message_round_trips(name: str, variant: str) -> None:
    codec = BitSignalCodec.for_message(name, variant)
    assert codec.variant.key == variant
    strategy = st.fixed_dictionaries({s.name: signal_value(s) for s in codec.variant.signals})

    @settings(max_examples=15, deadline=None)
    @given(strategy)
    def check(values: dict[str, float]) -> None:
        wire = codec.encode(values)
        assert len(wire) == codec.length
        back = codec.decode(wire)
        for s in codec.variant.signals:
            assert back[s.name] == pytest.approx(values[s.name], abs=abs(s.factor) * 1e-6 + 1e-12)
        assert codec.encode(back) == wire
        assert codec.check(wire) == []

    check()
    assert codec.decode(codec.encode()) == pytest.approx(
        {s.name: s.initial for s in codec.variant.signals}, abs=1e-6
    )



@pytest.mark.parametrize(("name", "variant"), INIT_VARIANTS)
def test_a_value_inside_the_range_tolerance_encodes_to_bytes_the_check_accepts(
    name: str, variant: str
) -> None:
    """Fuzz finding (init_codec): a value up to half a step outside the range is accepted, so
    it must encode to a raw value that decodes inside the range (0.5 for [1, 1] rounded to 0)."""
    codec = BitSignalCodec.for_message(name, variant)
    for s in codec.variant.signals:
        if s.is_float or max(abs(s.min), abs(s.max)) > 2**52:  # 128-bit IDs: no float slack
            continue
        rmin, rmax = (-(1 << (s.length - 1)), (1 << (s.length - 1)) - 1) if s.signed else (
            0, (1 << s.length) - 1)
        ends = sorted((rmin * s.factor + s.offset, rmax * s.factor + s.offset))
        if s.min < ends[0] or s.max > ends[1]:
            continue  # the seed's range exceeds the field (autofixHorizon SW7: documented)
        half = abs(s.factor) / 2
        for v in (s.min - half, s.max + half, s.min, s.max):
            wire = codec.encode({s.name: v})
            assert codec.check(wire) == [], (s.name, v)

def test_out_of_range_init_value_names_the_signal_and_range() -> None:
    codec = BitSignalCodec.for_message("Init_Params_Vision")
    with pytest.raises(LocalProtocolError, match=r"cameraHeight = 4.*\[0.5, 3.5\]"):
        codec.encode({"cameraHeight": 4.0})
    with pytest.raises(LocalProtocolError, match="unknown signal"):
        codec.encode({"noSuchSignal": 1})


def test_init_vision_has_both_versions_and_newest_is_default() -> None:
    assert BitSignalCodec.for_message("Init_Params_Vision").variant.key == "sw7"
    assert BitSignalCodec.for_message("Init_Params_Vision", "6.0").variant.key == "sw2_2"
    assert BitSignalCodec.for_message("0x92").message.name == "Init_Params_Vision"


# -- E2E ---------------------------------------------------------------------------------------
E2E_STRUCTS = [(n, k) for n, k in STRUCT_VARIANTS if LC.get(n, k).crc_plan]


@pytest.mark.parametrize(("name", "variant"), E2E_STRUCTS)
def test_flipping_a_protected_byte_is_detected_and_others_are_not(
    name: str, variant: str
) -> None:
    lay = LC.get(name, variant)
    values = layout_values(CAT, lay).example()
    buf = bytearray(lay.build(values))
    protect(buf, lay, E2EState())
    assert verify(bytes(buf), lay, None) == []
    covered = {o + i for p in lay.crc_plan for o, s in p.ranges for i in range(s)}
    crc_bytes = {p.crc_offset + i for p in lay.crc_plan for i in (0, 1)}
    for pos in range(lay.size):
        flipped = bytearray(buf)
        flipped[pos] ^= 0x01
        errors = verify(bytes(flipped), lay, None)
        if pos in covered or pos in crc_bytes:
            assert errors, f"flip at byte {pos} of {name} went unnoticed"
        else:
            assert errors == [], f"flip at unprotected byte {pos} of {name} flagged"


def test_host_vehicle_state_sw8_crc_uses_the_d5_signal_list() -> None:
    lay = LC.get("host_vehicle_state_t", "sw8")
    (plan,) = lay.crc_plan
    names = [n for n in ("rollingFrameCount", "vehicleVelocity", "vehicleYawRate",
                         "vehicleVelocityValidity", "vehicleYawRateValidity")]
    expect = [(lay.field(n).offset, lay.field(n).size) for n in names]
    flat = [(o + i) for o, s in plan.ranges for i in range(s)]
    assert flat == [(o + i) for o, s in expect for i in range(s)]
    values = layout_values(CAT, lay).example()
    buf = bytearray(lay.build(values))
    protect(buf, lay, None)
    from eyeq_spi.crc import crc16
    serial = b"".join(bytes(buf[o : o + s]) for o, s in expect)
    assert int.from_bytes(buf[plan.crc_offset : plan.crc_offset + 2], "little") == crc16(serial)


def test_rolling_counter_steps_and_a_jump_is_counted() -> None:
    codec = MessageCodec()
    msg = codec.message("EYEQ_VIS_FAILSAFE_MSG")
    values = layout_values(CAT, codec.layout(msg)).example()
    tx, rx = E2EState(), E2EState()
    frames = [codec.encode_dasp(msg.name, values, i, tx) for i in range(4)]
    for f in (frames[0], frames[1], frames[3]):  # frames[2] lost
        out = codec.decode(f, rx)
    assert rx.counter_errors == 1 and "counter jump" in out.errors[0]
    assert rx.crc_errors == 0


def test_e2e_mismatch_is_reported_not_raised() -> None:
    codec = MessageCodec()
    values = layout_values(CAT, codec.layout(codec.message("EYEQ_VIS_OBSTACLES_MSG"))).example()
    wire = bytearray(codec.encode_dasp("EYEQ_VIS_OBSTACLES_MSG", values, 0, E2EState()))
    good = bytes(wire)
    wire[4 + 22] ^= 0xFF  # visObs[0].physicalState.width: ASIL, in both CRCs
    state = E2EState()
    out = codec.decode(bytes(wire), state)
    assert out.name == "EYEQ_VIS_OBSTACLES_MSG" and out.fields
    assert state.crc_errors == 2  # the object's own CRC and the list's CRC
    assert all("E2E CRC mismatch" in e for e in out.errors)
    wire = bytearray(good)
    wire[4 + 30] ^= 0xFF  # visObs[0].physicalState.length: QM since SW9, list CRC only
    state = E2EState()
    codec.decode(bytes(wire), state)
    assert state.crc_errors == 1


# -- one entry point -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("data", "protocol", "error"),
    [
        (b"", "UNKNOWN", "empty"),
        (b"\x99\x00", "UNKNOWN", "unknown message"),
        (b"\x65\xE4\x00\x00" + bytes(10), "DASP", "BadHdr"),
        (b"\x65\x5F\x00\x00", "DASP", "BadHdr: unknown DASP data ID 0x5F"),
        (b"\x65\xE4", "DASP", "BadHdr"),
        (b"\x41\x00", "DIAG", "expected 116"),
        (b"\x05\x5E\x05\x09\x01", "MESP", "unknown MESP service/function"),
        (b"\x05\x5E\x05\x03\x81\x00", "MESP", "ret"),
        (b"\x03\x5E\x03\x02\x01\xff\xff\xff\xff", "MESP", "malformed"),
    ],
)
def test_bad_messages_are_reported_never_raised(data: bytes, protocol: str, error: str) -> None:
    out = MessageCodec().decode(data)
    assert out.protocol == protocol
    assert any(error in e for e in out.errors), out.errors


def test_rule_a_demultiplexing() -> None:
    assert classify(b"\x05\x5E\x05") == "MESP"
    assert classify(b"\x05\x5E\x06") == "UNKNOWN"
    assert classify(b"\x65") == "DASP" and classify(b"\x41") == "DIAG"
    assert classify(b"\x10") == "BOOT"


@pytest.mark.parametrize("fn", [f.name for f in CAT.mesp])
def test_every_mesp_function_round_trips(fn: str) -> None:
    codec = MessageCodec()
    f = codec.mesp.function(fn)
    sample = {"u8": 7, "u16": 300, "u32": 70000, "string": "/mesp/eeprom.data1",
              "bytes": b"\x00\x01\x02"}
    req = {p.name: sample[p.type] for p in f.request}
    rep = {p.name: sample[p.type] for p in f.reply}
    out = codec.decode(codec.mesp.encode_request(fn, 63, req))
    assert (out.name, out.header["counter"], out.header["reply"]) == (fn, 63, False)
    assert out.fields == req
    out = codec.decode(codec.mesp.encode_reply(fn, 63, 0, rep))
    assert out.header["reply"] and out.fields == {"ret": 0, **rep} and out.errors == []
    out = codec.decode(codec.mesp.encode_reply(fn, 5, 3, {}))
    assert out.fields == {"ret": 3} and out.errors == []


def test_diag_and_boot_carry_their_id_byte() -> None:
    codec = MessageCodec()
    for proto, ident in (("DIAG", 0x41), ("BOOT", 0x10)):
        msg = next(m for m in CAT.messages if m.protocol == proto)
        values = layout_values(CAT, codec.layout(msg)).example()
        wire = codec.encode_other(proto, values)
        assert wire[0] == ident
        out = codec.decode(wire)
        assert (out.protocol, out.fields, out.errors) == (proto, values, [])


def test_floats_are_ieee_binary32_little_endian() -> None:
    lay = LC.get("eyeq_polynomial_model_t", "sw2_2")
    values = layout_values(CAT, lay).example()
    first = lay.fields[0]
    assert first.type == "real32"
    values[first.name] = 1.5
    assert lay.build(values)[:4] == struct.pack("<f", 1.5)
