"""The packer's writers of the scene (eyeq_spi/sim/scene_write.py) against the reference (the
value dicts): arrays of structs written by the generated row writers (the elements past the rows
zeroed by slices), and constants written once per packer."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eyeq_spi.catalog.messages import catalog
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.sim.dasp_fast import DaspPacker
from eyeq_spi.sim.scene import Scene
from eyeq_spi.sim.scene_layout import (
    ONCOMING,
    REFLECT_KEYS,
    SIGN_KEYS,
    SPOT_KEYS,
    VEHICLE,
    child_struct,
    enum_code,
    struct_elements,
)
from eyeq_spi.sim.scene_layout import layout_node_for as node_for
from eyeq_spi.sim.scene_write import write_table
from tests.test_sim_dasp_fast import Twins

pytestmark = pytest.mark.twin  # runs a reference/fast twin: also run with EYEQ_SPI_EXACT=1

SWS = catalog().sw_versions
# (message, struct member, array member, columns)
TABLES = [("EYEQ_VIS_LIGHT_SENSOR_DATA_MSG", "activeLightSensorInfo", "activeLightSpots",
           SPOT_KEYS),
          ("EYEQ_VIS_LIGHT_SENSOR_DATA_MSG", "activeLightSensorInfo", "reflectiveSigns",
           REFLECT_KEYS),
          ("EYEQ_VIS_TRAFFIC_SIGNS_MSG", "tsrInfo", "trafficSigns", SIGN_KEYS)]
# finite values well past every member's range (float32's included) and integral ones
VALUE = st.one_of(st.floats(-1e40, 1e40, allow_nan=False), st.integers(-300, 70000),
                  st.sampled_from([0.5, 1.5, 2.5, -0.5, 254.5]))


def _write(values: dict[str, Any], name: str, member: str, array: str, keys: tuple[str, ...],
           rows: list[tuple[Any, ...]]) -> None:
    node = node_for(name, getattr(values, "template", None) or values)
    assert node is not None
    info = child_struct(values, node, member)
    assert info is not None
    elems, en = struct_elements(*info, array)
    write_table(elems, en, keys, rows)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(sw=st.sampled_from(SWS), table=st.sampled_from(TABLES), data=st.data())
def test_generated_row_writers_give_the_dict_paths_bytes(sw: str, table: Any,
                                                         data: st.DataObject) -> None:
    """Rows of any length, values out of range, then fewer rows: the emptied elements are
    zeroed as the reference zeroes them."""
    name, member, array, keys = table
    codec = MessageCodec(sw)
    msg = codec.cat.message(name)
    if not msg.exists_in(sw):
        return
    lay = codec.layout(msg)
    packer = DaspPacker(lay, msg.data_id)
    ref = lay.zero_values()
    info = child_struct(ref, node_for(name, ref), member)  # type: ignore[arg-type]
    count = len(struct_elements(*info, array)[0]) if info else 0
    if not count:
        return
    row = st.tuples(*[VALUE] * len(keys))
    for n in (data.draw(st.integers(0, count)), data.draw(st.integers(0, count))):
        rows = data.draw(st.lists(row, min_size=n, max_size=n))
        for values in (ref, packer.root):
            _write(values, name, member, array, keys, rows)  # type: ignore[arg-type]
        assert codec.encode_dasp(name, ref, 7, None) == packer.encode(7, None), (n, rows)


@pytest.mark.parametrize("huge_ints", [False, True], ids=["float64", "huge"])
@pytest.mark.parametrize("sw", [SWS[0], "sw4", SWS[-1]])
@pytest.mark.parametrize("table", TABLES, ids=lambda t: t[2])
def test_full_tables_of_extreme_values_then_fewer_rows(sw: str, table: Any,
                                                       huge_ints: bool) -> None:
    """Every element written, values beyond every range on both sides, then a few rows and
    none; integers beyond what float64 holds exactly too."""
    name, member, array, keys = table
    codec = MessageCodec(sw)
    msg = codec.cat.message(name)
    lay = codec.layout(msg)
    packer = DaspPacker(lay, msg.data_id)
    ref = lay.zero_values()
    info = child_struct(ref, node_for(name, ref), member)  # type: ignore[arg-type]
    assert info is not None
    elems, en = struct_elements(*info, array)
    count = len(elems)
    reals = [-1e40, 1e40, 0.4, -0.5, 1e6, -3.5]
    ints = [-300, 70000, 2.5, -0.5, 1e6, -1e6, 3.5] + ([1e40] if huge_ints else [])
    for n in (count, 2, 0):
        cols = [reals if getattr(en.members.get(key), "real", True) else ints for key in keys]
        rows = [tuple(c[(j + k) % len(c)] for k, c in enumerate(cols)) for j in range(n)]
        for values in (ref, packer.root):
            _write(values, name, member, array, keys, rows)  # type: ignore[arg-type]
        assert codec.encode_dasp(name, ref, 7, None) == packer.encode(7, None), n


@pytest.mark.parametrize("sw", ["sw4", SWS[-1]])
def test_the_road_writes_its_constants_again_after_a_reset(sw: str) -> None:
    """The road's constants are written once per packer; after the packer's reset (zeros)
    they are written again, as the reference's fresh template gets them."""
    twins = Twins(sw, seed=4, objects=15)
    road = "EYEQ_VIS_ROAD_DATA_MSG"
    for k in range(6):
        t = 1.0 + k / 18
        twins.step(t)
        if k == 3:
            twins.packers[road].reset()
            twins.values[road] = twins.codec.layout(twins.codec.cat.message(road)).zero_values()
        ref, packed = twins.messages_at(t, k)
        assert ref == packed, k


def _motion_reference(s: float, vx: float, vy: float, vrel: float, lane: int, kind: int,
                      speed: float, d: float, dtgt: float) -> tuple[int, int, int]:
    """The object motion rules one object at a time, first true condition wins (§13.2.2)."""
    def c(enum: str, name: str, v: int) -> int:
        return enum_code(f"object_motion_{enum}", name, v)

    moving, vehicle, changing = speed >= 0.3, kind <= ONCOMING, kind == VEHICLE
    status = (c("status", "moving", 1) if speed >= 2.0 else
              c("status", "Moving_slowly", 4) if moving else
              c("status", "Stopped", 3) if vehicle else c("status", "stationary", 2))
    crossing, oncoming = abs(vy) > max(abs(vx), 0.5), vx < -1.0
    category = next((code for cond, code in (
        (crossing, c("category", "Crossing", 7)), (oncoming, c("category", "Oncoming", 12)),
        (changing and abs(dtgt) < abs(d) - 0.5, c("category", "Moving_in", 5)),
        (changing and abs(dtgt) > abs(d) + 0.5, c("category", "Moving_out", 6)),
        (moving and lane == 0 and s > 0.0 and vx > 0.5, c("category", "Preceding", 11)),
        (moving and lane != 0 and vrel > 1.0 and changing, c("category", "Passing", 1)),
        (moving, c("category", "Moving", 10))) if cond), c("category", "Undefined", 0))
    orientation = next((code for cond, code in (
        (crossing and vy > 0, c("orientation", "Crossing_left", 6)),
        (crossing, c("orientation", "Crossing_right", 2)),
        (oncoming and vy > 0.3, c("orientation", "Oncoming_drifting_left", 5)),
        (oncoming and vy < -0.3, c("orientation", "Oncoming_drifting_right", 3)),
        (oncoming, c("orientation", "Oncoming", 4)),
        (moving and vy > 0.3, c("orientation", "Drifting_left", 7)),
        (moving and vy < -0.3, c("orientation", "Drifting_right", 1)),
        (moving, c("orientation", "Preceding", 8))) if cond), c("orientation", "Unknown", 0))
    return status, category, orientation


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(
    st.floats(-30, 200), st.floats(-40, 45), st.floats(-3, 3), st.floats(-20, 20),
    st.integers(-3, 3), st.integers(0, 3), st.floats(-12, 12), st.floats(-12, 12),
    st.sampled_from([0.0, 0.2999, 0.3, 1.0, 1.999, 2.0, 5.0])), min_size=1, max_size=15))
def test_motion_rule_tables_pick_the_first_true_condition(rows: list[tuple[Any, ...]]) -> None:
    """Scene._motion (the conditions as bits of one index into rule tables) gives, object by
    object, what the ordered rules give, thresholds included."""
    s, vx, vy, vrel, lane, kind, d, dtgt, speed = (np.array(col) for col in zip(*rows,
                                                                               strict=True))
    got = Scene._motion(s, vx, vy, vrel, lane.astype(np.int64), kind.astype(np.int64), speed,
                        speed >= 0.3, d, dtgt)
    want = [_motion_reference(float(r[0]), float(r[1]), float(r[2]), float(r[3]), int(r[4]),
                              int(r[5]), float(r[8]), float(r[6]), float(r[7])) for r in rows]
    assert got.T.tolist() == [list(w) for w in want]
