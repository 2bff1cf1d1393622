"""The simulated ``spidev`` and ``ft4222`` of tests/simwire must not drift from the real
packages: every name the adapters (eyeq_spi/phy/spidev_lines.py, ft4222_lines.py) use on a
driver module exists in the real package and in the simulated one, with the same parameters,
and the simulated modules offer nothing the real ones do not.

The real ``ft4222`` is read from its installed stubs (``ft4222.pyi``, what ``mypy --strict``
checks the adapters against) and its enums; the real ``spidev`` (a C extension without
signatures) from the signature line of each method's documentation. Each check is skipped,
saying why, when the real package is not installed (the ``bench`` extra)."""

from __future__ import annotations

import ast
import importlib.util
import inspect
import re
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
SIMWIRE = ROOT / "tests" / "simwire"
PHY = ROOT / "eyeq_spi" / "phy"


def _load(name: str, path: Path, package: bool = False) -> ModuleType:
    """A module of tests/simwire under a name of its own (the real package keeps its name)."""
    spec = importlib.util.spec_from_file_location(
        name, path, submodule_search_locations=[str(path.parent)] if package else None)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def fakes() -> tuple[ModuleType, ModuleType]:
    if "simwire" not in sys.modules:
        _load("simwire", SIMWIRE / "simwire.py")
    return (_load("simwire_spidev", SIMWIRE / "spidev.py"),
            _load("simwire_ft4222", SIMWIRE / "ft4222" / "__init__.py", package=True))


def used(source: Path, owners: set[str]) -> set[str]:
    """``owner.name`` of every attribute the adapter module takes from a driver object:
    ``owners`` are names (``ft4222``) or ``self.x`` attributes holding the driver's object."""
    out = set()
    for node in ast.walk(ast.parse(source.read_text())):
        if not isinstance(node, ast.Attribute):
            continue
        base = node.value
        owner = (base.id if isinstance(base, ast.Name) else
                 f"self.{base.attr}" if isinstance(base, ast.Attribute)
                 and isinstance(base.value, ast.Name) and base.value.id == "self" else None)
        if owner in owners:
            out.add(f"{owner}.{node.attr}")
    return out


def _parameters(fn: Any) -> list[tuple[str, bool]]:
    """(name, has a default) of each parameter but ``self``."""
    return [(p.name, p.default is not inspect.Parameter.empty)
            for p in inspect.signature(fn).parameters.values() if p.name != "self"]


def _stub_parameters(fn: ast.FunctionDef) -> list[tuple[str, bool]]:
    args = [a.arg for a in fn.args.args if a.arg != "self"]
    defaults = len(fn.args.defaults)
    return [(name, i >= len(args) - defaults) for i, name in enumerate(args)]


# -- ft4222 ----------------------------------------------------------------------------------
def test_the_simulated_ft4222_offers_what_the_adapters_use_as_the_real_one_does(
        fakes: tuple[ModuleType, ModuleType]) -> None:
    real = pytest.importorskip("ft4222", reason="the real ft4222 package (the bench extra) is "
                               "not installed: nothing to compare the simulated one with")
    stub_path = Path(real.__file__).with_name("ft4222.pyi")
    if not stub_path.exists():
        pytest.skip(f"the installed ft4222 ships no stubs at {stub_path}")
    stub = ast.parse(stub_path.read_text())
    functions = {n.name: n for n in stub.body if isinstance(n, ast.FunctionDef)}
    chip = next(n for n in stub.body if isinstance(n, ast.ClassDef) and n.name == "FT4222")
    methods = {n.name: n for n in chip.body if isinstance(n, ast.FunctionDef)}
    fake = fakes[1]
    names = used(PHY / "ft4222_lines.py", {"ft4222", "self.chip", "SPI", "SPIMaster",
                                           "SPISlave"})
    assert "self.chip.spiSlave_Read" in names and "ft4222.openBySerial" in names
    for name in sorted(names):
        owner, attr = name.rsplit(".", 1)
        if owner == "self.chip":
            assert attr in methods, f"the real FT4222 has no {attr}"
            assert _parameters(getattr(fake.FT4222, attr)) == \
                _stub_parameters(methods[attr]), attr
        elif owner == "ft4222" and attr in functions:
            assert _parameters(getattr(fake, attr)) == _stub_parameters(functions[attr]), attr
        elif owner == "ft4222":  # a class or an enum
            assert hasattr(real, attr) and hasattr(fake, attr), attr
            if attr == "SysClock":
                assert {m.name: m.value for m in fake.SysClock} == \
                    {m.name: m.value for m in real.SysClock}
        else:  # an enum of ft4222.SPI, SPIMaster, SPISlave
            real_enum, fake_enum = getattr(getattr(real, owner), attr), \
                getattr(getattr(fake, owner), attr)
            assert {m.name: m.value for m in fake_enum} == {m.name: m.value for m in real_enum}
    # nothing more than the real chip offers
    public = {n for n in vars(fake.FT4222) if not n.startswith("_")}
    assert public <= set(methods), public - set(methods)
    fake_functions = {n for n, v in vars(fake).items() if inspect.isfunction(v)
                      and v.__module__ == fake.__name__}
    assert fake_functions <= set(functions), fake_functions - set(functions)


# -- spidev ----------------------------------------------------------------------------------
_DOC_SIGNATURE = re.compile(r"^(\w+)\(([^)]*)\)")


def _doc_parameters(method: Any) -> list[str]:
    """The parameter names of a spidev method from its documentation's first line."""
    match = _DOC_SIGNATURE.match((method.__doc__ or "").strip())
    assert match, method.__doc__
    return [p.strip(" []") for p in match.group(2).split(",") if p.strip(" []")]


def test_the_simulated_spidev_offers_what_the_adapters_use_as_the_real_one_does(
        fakes: tuple[ModuleType, ModuleType]) -> None:
    real = pytest.importorskip("spidev", reason="the real spidev package (the bench extra) is "
                               "not installed: nothing to compare the simulated one with")
    fake = fakes[0]
    names = used(PHY / "spidev_lines.py", {"spidev", "dev", "self.dev"})
    assert "self.dev.writebytes2" in names and "spidev.SpiDev" in names
    for name in sorted(names):
        attr = name.rsplit(".", 1)[1]
        if name == "spidev.SpiDev":
            continue
        member = getattr(real.SpiDev, attr)
        assert hasattr(fake.SpiDev, attr) or hasattr(fake.SpiDev(), attr), attr
        if callable(member):
            params = [n for n, _ in _parameters(getattr(fake.SpiDev, attr))]
            assert params == _doc_parameters(member), attr
        else:  # a property of the device: mode, max_speed_hz, bits_per_word, lsbfirst
            assert type(member).__name__ == "getset_descriptor", attr
    public = {n for n in vars(fake.SpiDev) if not n.startswith("_")} | set(vars(fake.SpiDev()))
    public = {n for n in public if not n.startswith("_")}
    assert public <= set(dir(real.SpiDev)), public - set(dir(real.SpiDev))
