"""The catalogue's cache (``eyeq_spi/catalog/cache.py``): a second start reads what the first
parsed from ``specs/``, an edited, broken or foreign file never gives a stale or wrong catalogue,
and the libyaml loader reads ``specs/`` as the pure-Python one does."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from eyeq_spi.catalog import cache
from eyeq_spi.catalog.link import specs_dir
from eyeq_spi.catalog.messages import load_catalog
from eyeq_spi.errors import SpecError


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
    assert len(list((tmp_path / "cache").glob("catalog-*.pickle"))) == 2  # a new key beside


def test_several_installs_keep_their_own_caches(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two checkouts (or virtual environments) of one user, started in turn, each read their
    own cached catalogue; past KEEP_KEYS other keys, the oldest key's files go."""
    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(tmp_path / "cache"))
    keep = cache.KEEP_KEYS
    trees = [Path(shutil.copytree(specs_dir(), tmp_path / f"specs{i}")) for i in range(keep + 2)]
    keys = [cache.specs_digest(t)[:16] for t in trees]
    calls, load = _counting_loader()
    for _ in range(3):  # a, b, a, b, ...: each parsed once
        for tree in trees[:2]:
            cache.cached_catalog(tree, load)  # type: ignore[arg-type]
    assert calls == trees[:2]
    for k, tree in enumerate(trees[2:], start=3):  # more keys: past keep, trees[0] goes
        for p in (tmp_path / "cache").glob("catalog-*.pickle"):  # distinct ages, oldest first
            age = keys.index(p.name.split("-")[1].split(".")[0][:16])
            os.utime(p, (1000.0 + age, 1000.0 + age))
        cache.cached_catalog(tree, load)  # type: ignore[arg-type]
        assert len(list((tmp_path / "cache").glob("catalog-*.pickle"))) == min(k, keep + 1)
    calls.clear()
    cache.cached_catalog(trees[1], load)  # type: ignore[arg-type]
    assert calls == []  # the second oldest is still there
    cache.cached_catalog(trees[0], load)  # type: ignore[arg-type]
    assert calls == [trees[0]]


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


# -- single spec files through the cache (spec_file -> cache.cached_data)-----------------------

def _doc_loader() -> tuple[list[Path], object]:
    calls: list[Path] = []

    def load(path: Path) -> dict[str, object]:
        calls.append(path)
        doc: dict[str, object] = yaml.load(path.read_text(), Loader=yaml.CSafeLoader)
        return doc

    return calls, load


def _doc_start(root: Path, cache_dir: Path) -> tuple[bool, dict[str, object]]:
    """A new process reads ``link.yaml`` of ``root`` through the cache: (parsed it, the doc)."""
    code = ("import json, sys, yaml\n"
            "from pathlib import Path\n"
            "from eyeq_spi.catalog import cache\n"
            "parsed = []\n"
            "def load(path):\n"
            "    parsed.append(path)\n"
            "    return yaml.safe_load(path.read_text())\n"
            "root = Path(sys.argv[1])\n"
            "doc = cache.cached_data(root, 'link.yaml', lambda: load(root / 'link.yaml'))\n"
            "print(json.dumps([bool(parsed), doc]))\n")
    env = {k: v for k, v in os.environ.items() if k != "EYEQ_SPI_NO_CACHE"}
    out = subprocess.run([sys.executable, "-c", code, str(root)], capture_output=True,
                         text=True, timeout=120, check=True,
                         env={**env, "EYEQ_SPI_CACHE_DIR": str(cache_dir)})
    parsed, doc = json.loads(out.stdout)
    return parsed, doc


def test_a_single_spec_file_is_read_from_the_cache_on_the_next_start(
    specs_copy: Path, tmp_path: Path
) -> None:
    folder = tmp_path / "cache"
    first, second = _doc_start(specs_copy, folder), _doc_start(specs_copy, folder)
    want = json.loads(json.dumps(yaml.safe_load((specs_copy / "link.yaml").read_text())))
    assert first == (True, want)
    assert second == (False, first[1])
    (marshalled,) = folder.glob("doc-*-link.yaml.marshal")
    assert marshalled.stat().st_mode & 0o077 == 0

    path = specs_copy / "link.yaml"  # a new start after an edit: a new key
    path.write_text(path.read_text() + "\nextra_key_for_the_test: 1\n")
    parsed, third = _doc_start(specs_copy, folder)
    assert parsed and third["extra_key_for_the_test"] == 1

    key = cache.specs_digest(specs_copy)[:32]
    (marshalled,) = folder.glob(f"doc-{key}-link.yaml.marshal")
    marshalled.write_bytes(b"\xffnot marshal")  # corrupt: parsed again, never fatal
    assert _doc_start(specs_copy, folder) == (True, third)


def test_a_doc_marshal_cannot_hold_is_returned_uncached(
    specs_copy: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import datetime

    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(tmp_path / "cache"))
    calls: list[Path] = []

    def load(path: Path) -> dict[str, object]:
        calls.append(path)
        return {"when": datetime.date(2026, 1, 1)}  # YAML timestamps: marshal cannot hold them

    for _ in range(2):
        doc = cache.cached_data(specs_copy, "link.yaml", lambda: load(specs_copy / "link.yaml"))
        assert doc["when"].year == 2026
    assert len(calls) == 2 and not list((tmp_path / "cache").glob("doc-*"))


def test_the_pickled_catalogue_reads_raw_documents_on_demand(specs_copy: Path) -> None:
    """``Catalog.raw`` pickles as its root only (the raw YAML was 3/4 of the cache's bytes) and
    reads a file when asked, with the same content as a fresh load."""
    import pickle

    fresh = load_catalog(specs_copy)
    blob = pickle.dumps(fresh, protocol=pickle.HIGHEST_PROTOCOL)
    again = pickle.loads(blob)
    assert len(blob) < 400_000 and not again.raw._docs
    assert again.raw["mesp.yaml"] == fresh.raw["mesp.yaml"]
    assert "capture.yaml" in again.raw and len(again.raw) == len(list(specs_copy.rglob("*.yaml")))
    with pytest.raises(KeyError):
        again.raw["no_such_file.yaml"]


def test_the_key_changes_when_a_file_is_touched_or_added(specs_copy: Path) -> None:
    before = cache.specs_digest(specs_copy)
    assert cache.specs_digest(specs_copy) == before
    path = specs_copy / "link.yaml"
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))  # same bytes, new mtime
    touched = cache.specs_digest(specs_copy)
    (specs_copy / "can" / "extra.yaml").write_text("x: 1\n")
    assert len({before, touched, cache.specs_digest(specs_copy)}) == 3


def test_the_names_index_agrees_with_the_catalogue() -> None:
    from eyeq_spi.catalog.messages import catalog
    from eyeq_spi.cli import args as ca

    cat, idx = catalog(), ca._index()
    assert idx == ca._build_index()
    assert idx["default_sw"] == cat.default_sw and len(idx["messages"]) == len(cat.messages)
    assert ca.fatal_code("intrinsic_calibration_mismatch") == 22 == ca.fatal_code("0x16")
    assert ca.eyeq_dasp_message("0xe4") == "EYEQ_VIS_OBSTACLES_MSG"
    assert ca.mesp_function("0x05/0x04") == next(
        f.name for f in cat.mesp if (f.service, f.function) == (5, 4))
    assert ca.sw_release("8.1") == "sw8_1"
