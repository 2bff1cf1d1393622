"""Where the public decoders of ExtLogData2 are wrong, ours must be right: one
test per error, each built so that the public decoder's reading fails it. Frames are decoded by
our DBC database and by ``can decode``'s decoder (which also reports DLC and invalid values)."""

from __future__ import annotations

import math
import struct

import pytest

can = pytest.importorskip("can", reason="needs the [can] extra (python-can)")
pytest.importorskip("cantools", reason="needs the [can] extra (cantools)")

from eyeq_spi.can.dbc import database  # noqa: E402
from eyeq_spi.can.decode import CanDecoder  # noqa: E402
from eyeq_spi.catalog.can import protocol  # noqa: E402


def lane_frame(curv: int = 0, heading: int = 0, bits_28_31: int = 0, yaw: int = 0x7FFF,
               pitch: int = 0x7FFF) -> bytes:
    """0x737 as seed 001 §8.2.2.8 / 000 §3 lay it out: curvature 16 bits, heading 12 bits,
    CA / right LDW / left LDW / NA in bits 28-31, yaw and pitch 16 bits offset-binary."""
    word = (heading & 0xFFF) | (bits_28_31 << 12)
    return struct.pack("<hHHH", curv, word, yaw, pitch)


def decode(data: bytes, frame_id: int = 0x737) -> dict[str, object]:
    return CanDecoder("extlog2").decode(
        can.Message(arbitration_id=frame_id, data=data, is_extended_id=False), 0)


def lane(data: bytes) -> dict[str, float]:
    out: dict[str, float] = database("extlog2").get_message_by_name("Lane").decode(
        data, decode_choices=False)
    return out


def test_curvature_is_3_81e_6_per_raw_step_not_apollos_4e_6() -> None:
    raw = 10000  # 0.0381 1/m, a 26 m radius
    got = lane(lane_frame(curv=raw))["Lane_Curvature"]
    assert math.isclose(got, raw * 3.81e-6, rel_tol=1e-12)  # 001 line 1821, 000 line 119
    apollo = raw * 4e-6
    assert abs(apollo - got) / got > 0.04  # Apollo's reading is 5% off and fails here
    assert math.isclose(lane(lane_frame(curv=-raw))["Lane_Curvature"], -got)  # signed


@pytest.mark.parametrize(("name", "div"), [("Yaw_Angle", 1024), ("Pitch_Angle", 1024 * 512)])
def test_yaw_and_pitch_are_offset_binary_raw_7fff_is_zero(name: str, div: int) -> None:
    frame = lane_frame()  # the public log's 0x7FFF in both
    assert lane(frame)[name] == pytest.approx(0.0, abs=1e-12)
    apollo = struct.unpack("<h", b"\xff\x7f")[0] / div  # signed, no offset: +31.999 rad yaw
    assert apollo > 0.06  # the public reading is far from 0 and fails the line above
    below = lane_frame(**{name.split("_")[0].lower(): 0x7FFF - 100})
    assert lane(below)[name] == pytest.approx(-100 / div, rel=1e-9)  # negative below 0x7FFF


def test_pitch_scale_is_1024_times_512() -> None:
    raw = 0x7FFF + 5120
    got = lane(lane_frame(pitch=raw))["Pitch_Angle"]
    assert math.isclose(got, 5120 / 1024 / 512, rel_tol=1e-12)  # (HEX-0x7FFF)/1024/512
    for wrong in (got * 1.2, got / 1.2, got * 0.8):  # a 20% scale error fails the line above
        assert not math.isclose(wrong, 5120 / 1024 / 512, rel_tol=0.05)
    spec = protocol("extlog2").message("Lane").signal("Pitch_Angle")
    assert (spec.min, spec.max) == (-0.05, 0.05)  # 001 line 1853: the printed range


def test_0x738_is_six_bytes_and_close_car_is_read() -> None:
    status = database("extlog2").get_message_by_name("Obstacle_Status")
    assert status.length == 6  # 001 and 000 print bytes 0-5; the v2.32 DBC says 7
    data = bytes([3, 0x42, 2, 0, 0, 0x01])  # 3 obstacles, Close_Car = byte 5 bit 0
    rec = decode(data, 0x738)
    assert rec["errors"] == [] and rec["fields"]["Close_Car"] == 1  # type: ignore[index]
    assert rec["fields"]["Num_Obstacles"] == 3  # type: ignore[index]
    seven = decode(data + b"\x00", 0x738)  # what a DLC-7 reading expects: a real unit's
    assert any("DLC 7, spec 6" in e for e in seven["errors"])  # type: ignore[attr-defined]
    close = protocol("extlog2").message("Obstacle_Status").signal("Close_Car")
    assert close.bits() == {40} and max(close.bits()) < 6 * 8


def test_invalid_heading_bits_of_0x737_are_heading_not_guard_rails() -> None:
    spec = protocol("extlog2").message("Lane")
    heading = spec.signal("Lane_Heading")
    assert heading.bits() == set(range(16, 28)) and heading.invalid == 0x800
    for s in spec.signals:  # no other signal (guard rails or else) reads heading bits
        assert s is heading or not s.bits() & heading.bits(), s.name
    rec = decode(lane_frame(heading=0x800))  # the invalid heading 800h: byte 3 bit 3 set
    assert rec["invalid"] == ["Lane_Heading"]
    f = rec["fields"]
    assert (f["CA"], f["Right_LDW_Availability"], f["Left_LDW_Availability"]) == (0, 0, 0)  # type: ignore[index]
    # bits 29/30 are the LDW availabilities; they leave the heading alone
    rec = decode(lane_frame(heading=0x123, bits_28_31=0b0110))
    assert rec["fields"]["Lane_Heading"] == pytest.approx(0x123 * 0.0005)  # type: ignore[index]
    assert (rec["fields"]["Right_LDW_Availability"],  # type: ignore[index]
            rec["fields"]["Left_LDW_Availability"]) == (1, 1)  # type: ignore[index]
    assert rec["invalid"] == []
