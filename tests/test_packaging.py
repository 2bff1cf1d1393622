"""A regular install (a wheel, `pip install .`) carries specs/ inside the package: the project
reads every wire format from there (``eyeq_spi/specs`` is a link to the repository's ``specs/``;
setuptools copies what it points to)."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

from eyeq_spi.spec.link import specs_dir

ROOT = Path(__file__).resolve().parents[1]


def test_the_package_finds_specs_inside_itself() -> None:
    assert specs_dir() == ROOT / "eyeq_spi" / "specs"
    assert (ROOT / "eyeq_spi" / "specs").resolve() == (ROOT / "specs").resolve()


def test_a_wheel_carries_every_spec_file(tmp_path: Path) -> None:
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", str(ROOT),
                        "-w", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    (wheel,) = tmp_path.glob("eyeq_spi-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    want = {f"eyeq_spi/{p.relative_to(ROOT).as_posix()}"
            for p in (ROOT / "specs").rglob("*") if p.is_file()}
    assert want and want <= names, sorted(want - names)[:10]
    assert "eyeq_spi/py.typed" in names
