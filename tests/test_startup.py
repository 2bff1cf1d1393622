"""The start-up cache of the catalogue (``eyeq_spi/spec/cache.py``) and the libyaml loader."""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from eyeq_spi.errors import SpecError
from eyeq_spi.spec import cache
from eyeq_spi.spec.catalog import load_catalog
from eyeq_spi.spec.link import specs_dir


@pytest.fixture
def specs_copy(tmp_path: Path) -> Path:
    return Path(shutil.copytree(specs_dir(), tmp_path / "specs"))


@dataclass(frozen=True)
class _Small:
    """Stands in for the catalogue where only the caching is under test (fast)."""

    default_sw: str
    files: int


def _counting_loader(real: bool = False) -> tuple[list[Path], object]:
    calls: list[Path] = []

    def load(root: Path) -> object:
        calls.append(root)
        if real:
            return load_catalog(root)
        text = (root / "sw_versions.yaml").read_text()
        return _Small(text.rsplit("default: ", 1)[1].strip(), len(list(root.rglob("*"))))

    return calls, load


def test_second_start_reads_the_cache_and_gets_the_same_catalogue(
    specs_copy: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("EYEQ_SPI_NO_CACHE", raising=False)
    calls, load = _counting_loader(real=True)
    first = cache.cached_catalog(specs_copy, load)  # type: ignore[arg-type]
    second = cache.cached_catalog(specs_copy, load)  # type: ignore[arg-type]
    assert len(calls) == 1 and second == first
    files = list((tmp_path / "cache").glob("catalog-*.pickle"))
    assert len(files) == 1 and (files[0].stat().st_mode & 0o077) == 0


def test_an_edited_spec_file_misses_the_cache(
    specs_copy: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(tmp_path / "cache"))
    calls, load = _counting_loader()
    before = cache.cached_catalog(specs_copy, load)  # type: ignore[arg-type]
    path = specs_copy / "sw_versions.yaml"
    path.write_text(path.read_text().replace("default: sw9", "default: sw8_1"))
    after = cache.cached_catalog(specs_copy, load)  # type: ignore[arg-type]
    assert len(calls) == 2
    assert before.default_sw == "sw9" and after.default_sw == "sw8_1"  # type: ignore[attr-defined]
    assert len(list((tmp_path / "cache").glob("catalog-*.pickle"))) == 1  # old key removed


def test_a_corrupt_cache_file_is_rebuilt(
    specs_copy: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(tmp_path / "cache"))
    calls, load = _counting_loader()
    cache.cached_catalog(specs_copy, load)  # type: ignore[arg-type]
    (pickled,) = (tmp_path / "cache").glob("catalog-*.pickle")
    pickled.write_bytes(b"\x80\x05garbage")
    cat = cache.cached_catalog(specs_copy, load)  # type: ignore[arg-type]
    assert len(calls) == 2 and cat.default_sw == "sw9"  # type: ignore[attr-defined]


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0,
                    reason="root writes into a read-only directory anyway")
def test_an_unwritable_cache_directory_falls_back_to_parsing(
    specs_copy: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:  # pragma: no cover - CI runs as root
    ro = tmp_path / "ro"
    ro.mkdir(mode=0o500)
    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(ro / "cache"))
    calls, load = _counting_loader()
    cache.cached_catalog(specs_copy, load)  # type: ignore[arg-type]
    assert len(calls) == 1


def test_a_cache_path_that_is_a_file_falls_back_to_parsing(
    specs_copy: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("x")  # mkdir fails even for root
    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(blocker / "cache"))
    calls, load = _counting_loader()
    a = cache.cached_catalog(specs_copy, load)  # type: ignore[arg-type]
    b = cache.cached_catalog(specs_copy, load)  # type: ignore[arg-type]
    assert len(calls) == 2 and a == b


def test_a_broken_spec_is_an_error_and_is_not_cached(
    specs_copy: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(tmp_path / "cache"))
    (specs_copy / "constants.yaml").write_text("constants: [unclosed\n")
    with pytest.raises(SpecError):
        cache.cached_catalog(specs_copy, load_catalog)
    assert not list((tmp_path / "cache").glob("catalog-*.pickle"))


def test_libyaml_and_the_pure_python_loader_read_specs_alike() -> None:
    paths = sorted(specs_dir().rglob("*.yaml"), key=lambda p: p.stat().st_size)
    for path in paths[:: max(1, len(paths) // 6)]:  # a spread of sizes: the slow loader is slow
        text = path.read_text(encoding="utf-8")
        assert yaml.load(text, Loader=yaml.CSafeLoader) == yaml.safe_load(text), path
