"""Seeded slice of the fuzz targets, on every CI run: coverage-free seeded
inputs into each target of ``tests/fuzz`` and the ``dissect`` subprocess on every input format.
``tools/fuzz.py --budget S`` runs the coverage-guided long version under atheris."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from eyeq_spi.codec.intrinsic import eeprom_codec
from eyeq_spi.faults.rig import Scene, rig
from eyeq_spi.host.machine import HostState
from tests.fuzz import dissect_target
from tests.fuzz.app_targets import eeprom_image, host_eeprom
from tests.fuzz.core import Reader
from tests.fuzz.registry import run_slice

SLICE = {
    "link_rx": 1500,
    "transport_pair": 300,
    "transport_pair_wire": 200,
    "decoders": 500,
    "init_codec": 800,
    "host_messages": 150,
    "sim_messages": 150,
    "host_eeprom": 3,
}


def _show(findings: list[tuple[str, bytes]]) -> list[tuple[str, str]]:
    return [(what, data.hex()[:200]) for what, data in findings]


@pytest.mark.parametrize("name", sorted(SLICE))
def test_fuzz_slice_finds_nothing(name: str) -> None:
    res = run_slice(name, SLICE[name], seed=9)
    assert res.inputs == SLICE[name]
    assert not res.findings, _show(res.findings)


def test_eeprom_with_nan_in_the_distortion_parameters_is_a_camera_fault() -> None:
    # the case the host_eeprom fuzz target found, as it builds it: CRC-valid, CCAM_distorParams_m_*
    # set to NaN (each entry: signal index, then pick 0 = the NaN bit pattern)
    names = [s.name for s in eeprom_codec().variant.signals]
    picks = [names.index(n) for n in names if n.startswith("CCAM_distorParams_m_")][:4]
    assert picks and max(picks) < 256
    data = bytes([len(picks) - 1]) + b"".join(bytes([i, 0]) for i in picks)
    image, touched = eeprom_image(Reader(data))
    assert all(n.startswith("CCAM_distorParams_m_") for n in touched)
    emu = rig(fresh_nvm=True, scene=Scene(0, 0, 0))
    emu.sim.eeprom[:] = image
    emu.run_for(3.0, stop=lambda: emu.host.state is HostState.FAILED)
    assert emu.host.state is HostState.FAILED
    assert any(n in (emu.host.problem or "") for n in touched), emu.host.problem
    host_eeprom(data)  # and the target itself finds nothing


def test_dissect_every_input_format_as_a_subprocess(tmp_path: Path) -> None:
    log = dissect_target.seed_log()
    files = dissect_target.make_inputs(random.Random(9), log, tmp_path, per_format=5)
    results = dissect_target.run_files(files, per_file=10.0)
    dissect_target.check(results)
    assert {r["rc"] for r in results} >= {0, 2}  # the seed capture is clean; mutants are not
