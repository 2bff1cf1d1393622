"""A regular install (a wheel, `pip install .`) carries specs/ inside the package: the project
reads every wire format from there (``eyeq_spi/specs`` is a link to the repository's ``specs/``;
setuptools copies what it points to)."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

from eyeq_spi.catalog.link import specs_dir

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


def test_the_readme_install_runs_the_demo(tmp_path: Path) -> None:
    """The README's first command: a regular install into a fresh venv, then ``eyeq-spi demo
    --duration 5``. The venv sees this Python's packages (no download in a test) but not its
    editable install, installs the wheel without dependencies, and must run the installed copy,
    not this checkout."""
    wheels = tmp_path / "wheels"
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", str(ROOT),
                        "-w", str(wheels)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    (wheel,) = wheels.glob("eyeq_spi-*.whl")
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    py, exe = venv / "bin" / "python", venv / "bin" / "eyeq-spi"
    site_dir = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()"
                               "['purelib'])"], capture_output=True, text=True, check=True)
    # this Python's packages as plain paths: their .pth files (our editable install) stay off
    (Path(site_dir.stdout.strip()) / "deps.pth").write_text(
        "\n".join(p for p in sys.path if p.endswith("site-packages")) + "\n")
    r = subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index",
                        str(wheel)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    where = subprocess.run([str(py), "-c", "import eyeq_spi; print(eyeq_spi.__file__)"],
                           cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert str(venv) in where.stdout, where.stdout + where.stderr
    demo = subprocess.run([str(exe), "demo", "--duration", "5"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert demo.returncode == 0, demo.stdout[-2000:] + demo.stderr[-2000:]
    assert "RUNNING_VISION" in demo.stdout + demo.stderr


def test_the_oldest_versions_ci_tests_are_the_floors_of_pyproject() -> None:
    """``.ci/oldest.txt`` (what ``tools/check.py --oldest`` installs) pins every direct
    dependency with a ``>=`` floor to exactly that floor, so CI tests what the pins allow."""
    import re
    import tomllib

    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    floors = {}
    for req in meta["dependencies"] + meta["optional-dependencies"]["test"]:
        m = re.match(r"([A-Za-z0-9_.\-]+)(\[.*\])?\s*>=\s*([0-9.]+)", req)
        if m:
            floors[m.group(1).lower()] = m.group(3)
    pins = {}
    for line in (ROOT / ".ci" / "oldest.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, _, version = line.partition("==")
            pins[name.strip().lower()] = version.strip()
    assert pins == floors
