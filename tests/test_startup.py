"""The start-up cache of the catalogue (``eyeq_spi/catalog/cache.py``) and the libyaml loader."""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from eyeq_spi.catalog import cache
from eyeq_spi.catalog.link import specs_dir
from eyeq_spi.catalog.messages import load_catalog
from eyeq_spi.errors import SpecError
from eyeq_spi.twins import exact

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1


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
    monkeypatch.setattr(cache, "KEEP_KEYS", 0)
    calls, load = _counting_loader()
    before = cache.cached_catalog(specs_copy, load)  # type: ignore[arg-type]
    path = specs_copy / "sw_versions.yaml"
    path.write_text(path.read_text().replace("default: sw9", "default: sw8_1"))
    after = cache.cached_catalog(specs_copy, load)  # type: ignore[arg-type]
    assert len(calls) == 2
    assert before.default_sw == "sw9" and after.default_sw == "sw8_1"  # type: ignore[attr-defined]
    assert len(list((tmp_path / "cache").glob("catalog-*.pickle"))) == 1  # old key removed


def test_several_installs_keep_their_own_caches(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two checkouts (or virtual environments) of one user, started in turn, each read their
    own cached catalogue; past KEEP_KEYS other keys, the oldest key's files go."""
    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(cache, "KEEP_KEYS", 2)
    trees = [Path(shutil.copytree(specs_dir(), tmp_path / f"specs{i}")) for i in range(4)]
    calls, load = _counting_loader()
    for _ in range(3):  # a, b, a, b, ...: each parsed once
        for tree in trees[:2]:
            cache.cached_catalog(tree, load)  # type: ignore[arg-type]
    assert calls == trees[:2]
    for tree in trees[2:]:  # two more keys: the oldest (trees[0]) is pruned
        for p in (tmp_path / "cache").glob("catalog-*.pickle"):  # distinct ages, oldest first
            key = p.name.split("-")[1].split(".")[0]
            age = [cache.specs_digest(t)[:16] for t in trees].index(key)
            os.utime(p, (1000.0 + age, 1000.0 + age))
        cache.cached_catalog(tree, load)  # type: ignore[arg-type]
        assert len(list((tmp_path / "cache").glob("catalog-*.pickle"))) == 3
    calls.clear()
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


# -- what a start imports. Not timed: the mechanism is guarded. ---

HEAVY = ("numpy", "construct", "yaml", "rich", "matplotlib", "pyarrow", "cantools")
_PROBE = (
    "import io, json, sys, contextlib\n"
    "from eyeq_spi.cli import main\n"
    "with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):\n"
    "    try:\n"
    "        rc = main(json.loads(sys.argv[1]))\n"
    "    except SystemExit as exc:  # --help\n"
    "        rc = exc.code\n"
    "print(json.dumps([rc, sorted(m for m in json.loads(sys.argv[2]) if m in sys.modules)]))\n"
)


@pytest.fixture(scope="module")
def warm_cache(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """A filled cache directory (the first start of a user parses specs/ once) and a 3-transfer
    hex capture."""
    import subprocess
    import sys

    d = tmp_path_factory.mktemp("startup")
    env = {**os.environ, "EYEQ_SPI_CACHE_DIR": str(d / "cache")}
    env.pop("EYEQ_SPI_NO_CACHE", None)
    hexfile = d / "small.hex"
    zeros = bytes(128).hex()
    hexfile.write_text("".join(f"{t:.6f} h2e {zeros}\n" for t in (0.0, 0.01, 0.02)))
    subprocess.run([sys.executable, "-c", _PROBE, f'["dissect", "{hexfile}"]', "[]"], env=env,
                   check=True, capture_output=True, timeout=120)
    subprocess.run([sys.executable, "-c", _PROBE, '["spec", "list"]', "[]"], env=env,
                   check=True, capture_output=True, timeout=120)
    # 2 s of full-load traffic (560 kB: the batch path) with MESP requests and replies in it,
    # as pcapng and as the raw EyeQ -> host channel (whose release is inferred from the traffic)
    big = d / "big.pcapng"
    subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "demo", "--virtual-time", "--duration",
                    "2", "--objects", "15", "--signs", "20", "--light-spots", "15", "--capture",
                    str(big)], env=env, check=True, capture_output=True, timeout=120)
    from eyeq_spi.capture.pcapng_io import read_pcapng

    with big.open("rb") as fh:
        raw = b"".join(r.data for r in read_pcapng(fh) if r.direction == "e2h")
    (d / "big.bin").write_bytes(raw)
    return {**env, "SMALL_HEX": str(hexfile), "BIG_PCAPNG": str(big),
            "BIG_RAW": str(d / "big.bin")}


def _imports(argv: list[str], env: dict[str, str], watch: tuple[str, ...]) -> tuple[int, list[str]]:
    import json
    import subprocess
    import sys

    for name in ("SMALL_HEX", "BIG_PCAPNG", "BIG_RAW"):
        argv = [a.replace(name, env[name]) for a in argv]
    cmd = [sys.executable, "-c", _PROBE, json.dumps(argv), json.dumps(watch)]
    # the first run refills the cache should specs/ have changed since (as a user's second start)
    subprocess.run(cmd, env=env, check=True, capture_output=True, timeout=120)
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True, timeout=120)
    rc, mods = json.loads(out.stdout.strip().splitlines()[-1])
    return int(rc), list(mods)


@pytest.mark.parametrize(("argv", "rc", "allowed"), [
    (["--help"], 0, ()),
    (["host", "--port", "socket://127.0.0.1"], 2, ()),
    (["dissect", "--id", "zz", "SMALL_HEX"], 2, ()),
    (["nonsense"], 2, ()),
    (["spec", "list"], 0, ()),
    (["spec", "show", "obstacles"], 0, ()),
    # a small capture (of bad frames: exit 1): none of them (MESP parameters are parsed
    # without construct)
    (["dissect", "SMALL_HEX"], 1, ()),
    (["dissect", "SMALL_HEX", "--stats", "--json"], 1, ()),
    # the batch path (a big capture with MESP in it): numpy, and nothing else
    (["dissect", "BIG_PCAPNG", "--stats"], 0, ("numpy",)),
    (["dissect", "BIG_RAW", "--direction", "e2h", "--stats", "--json"], 0, ("numpy",)),
    (["dissect", "BIG_PCAPNG", "--json"], 0, ("numpy",)),
])
def test_quick_commands_do_not_import_heavy_libraries(
    warm_cache: dict[str, str], argv: list[str], rc: int, allowed: tuple[str, ...]
) -> None:
    got_rc, mods = _imports(argv, warm_cache, HEAVY)
    assert got_rc == rc
    if "numpy" in allowed and exact():
        allowed = (*allowed, "construct")  # the references decode with construct (exact())
    assert [m for m in mods if m not in allowed] == [], f"{argv} imported {mods}"


@pytest.mark.skipif(exact(), reason="EYEQ_SPI_EXACT=1: the exact engine reads every capture "
                    "and decodes with construct; this holds the batch path to its imports")
def test_batch_stats_imports_nothing_it_does_not_use(warm_cache: dict[str, str]) -> None:
    """``dissect --stats`` of a big capture (MESP latencies in its statistics): no construct (MESP
    parameters parsed by hand), no statistics (the median by hand), no tempfile (the cache is only
    read), no process pool."""
    watch = ("construct", "yaml", "statistics", "tempfile", "concurrent", "pyarrow", "rich",
             "orjson")
    rc, mods = _imports(["dissect", "BIG_PCAPNG", "--stats"], warm_cache, watch)
    assert rc == 0 and mods == []


@pytest.mark.skipif(exact(), reason="EYEQ_SPI_EXACT=1: the exact engine reads every capture; "
                    "this holds the batch path to its imports")
def test_batch_stats_of_a_pcapng_imports_no_other_reader_or_writer(
    warm_cache: dict[str, str]
) -> None:
    """``dissect --stats`` of a pcapng file: the pcapng sniffer answers first, so no
    logic-analyzer reader is imported; no csv (only tables write it), no threading (only the
    capture writer's idle flush starts a thread), no crcmod (the link's CRC-16/CCITT-FALSE is
    ``binascii.crc_hqx``; crcmod computes only other variants)."""
    import json
    import subprocess
    import sys

    watch = ("eyeq_spi.logic.saleae", "eyeq_spi.logic.saleae_ref", "eyeq_spi.logic.saleae_types",
             "eyeq_spi.logic.vcd", "eyeq_spi.logic.vcd_ref", "csv", "threading", "crcmod")
    # what the batch path's own dependencies import at some of their allowed versions (numpy
    # 1.26 imports threading) is theirs, not ours
    deps = subprocess.run(
        [sys.executable, "-c", "import json, sys, numpy, platformdirs; "
         f"print(json.dumps([m for m in {list(watch)!r} if m in sys.modules]))"],
        env=warm_cache, check=True, capture_output=True, text=True, timeout=120)
    theirs = set(json.loads(deps.stdout))
    rc, mods = _imports(["dissect", "BIG_PCAPNG", "--stats"], warm_cache, watch)
    assert rc == 0 and [m for m in mods if m not in theirs] == []


_COMPILES = (
    "import builtins, io, json, sys, contextlib\n"
    "seen = []\n"
    "real = builtins.compile\n"
    "def counting(source, *args, **kw):\n"
    "    seen.append(isinstance(source, str) and args[:2] == ('<string>', 'exec'))\n"
    "    return real(source, *args, **kw)\n"
    "from eyeq_spi.cli import main\n"
    "builtins.compile = counting\n"
    "with contextlib.redirect_stdout(io.StringIO()):\n"
    "    rc = main(json.loads(sys.argv[1]))\n"
    "print(json.dumps([rc, sum(seen)]))\n"
)


def test_a_second_start_compiles_no_generated_code(
    warm_cache: dict[str, str], tmp_path: Path
) -> None:
    """The first ``dissect --stats`` start with an empty cache compiles generated code (the
    methods dataclasses writes, the fast layout codecs of the MESP and boot messages) and keeps
    it; the next compiles none."""
    import json
    import subprocess
    import sys

    env = {**warm_cache, "EYEQ_SPI_CACHE_DIR": str(tmp_path / "cache")}
    argv = json.dumps(["dissect", warm_cache["BIG_PCAPNG"], "--stats"])
    counts = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", _COMPILES, argv], env=env, check=True,
                             capture_output=True, text=True, timeout=120)
        counts.append(json.loads(out.stdout.strip().splitlines()[-1]))
    assert counts[0][0] == counts[1][0] == 0
    assert counts[0][1] > 50 and counts[1][1] == 0, counts


_COLLECTIONS = (
    "import gc, io, json, sys, contextlib\n"
    "older, explicit = [], []\n"
    "gc.callbacks.append(lambda phase, info: phase == 'start' and info['generation'] and "
    "older.append(1))\n"
    "real = gc.collect\n"
    "def counting(*args):\n"
    "    explicit.append(1)\n"
    "    return real(*args)\n"
    "gc.collect = counting\n"
    "from eyeq_spi.cli import main\n"
    "argv = json.loads(sys.argv[1])\n"
    "older.clear()  # from here: the command\n"
    "with contextlib.redirect_stdout(io.StringIO()):\n"
    "    rc = main(argv)\n"
    "print(json.dumps([rc, len(older) - len(explicit), gc.isenabled(), gc.get_freeze_count()]))\n"
)


def test_dissect_leaves_what_its_start_loads_out_of_the_collections(
    warm_cache: dict[str, str]
) -> None:
    """``dissect`` turns the automatic cyclic collector off for the whole command: no automatic
    collection of the older generations re-scans the modules and catalogue a start loaded (the
    dissection's own paced collections remain); the collector is on and nothing frozen after."""
    import json
    import subprocess
    import sys

    argv = json.dumps(["dissect", warm_cache["BIG_PCAPNG"], "--stats"])
    out = subprocess.run([sys.executable, "-c", _COLLECTIONS, argv], env=warm_cache, check=True,
                         capture_output=True, text=True, timeout=120)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == [0, 0, True, 0]


def test_the_probe_sees_a_heavy_import() -> None:
    """The guard above can fail: a command that needs yaml (no cache) is seen importing it."""
    import json
    import subprocess
    import sys

    env = {**os.environ, "EYEQ_SPI_NO_CACHE": "1"}
    out = subprocess.run([sys.executable, "-c", _PROBE, '["spec", "show", "0xE4"]',
                          json.dumps(HEAVY)], env=env, check=True, capture_output=True, text=True,
                         timeout=120)
    assert "yaml" in json.loads(out.stdout.strip().splitlines()[-1])[1]


def test_the_parser_of_one_command_is_the_full_parser_for_that_command() -> None:
    """main() builds only the command it runs; COMMANDS must list every command with its help, in
    the order of the full parser, and each command's parser must not depend on the others."""
    import argparse

    from eyeq_spi.cli import COMMANDS, build_parser

    def subs(p: argparse.ArgumentParser) -> tuple[dict[str, str], dict[str, str]]:
        act = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
        helps = {c.dest: str(c.help) for c in act._choices_actions}
        return helps, {n: sp.format_help() for n, sp in act.choices.items()}

    full_help, full = subs(build_parser())
    assert list(full_help.items()) == list(COMMANDS.items())
    assert build_parser("").format_help() == build_parser().format_help()
    for name in COMMANDS:
        helps, one = subs(build_parser(name))
        assert helps == full_help and one[name] == full[name], name


def test_a_layout_builds_its_construct_codec_only_when_asked() -> None:
    from eyeq_spi.catalog.messages import catalog
    from eyeq_spi.codec.layout import LayoutCache

    cat = catalog()
    msg = next(m for m in cat.messages if m.data_id == 0xE4 and m.protocol == "DASP")
    lay = LayoutCache(cat).get(msg.payload, cat.default_sw)
    assert lay._struct is None and all(c._struct is None for c in lay.children.values())
    assert lay.struct.sizeof() == lay.size  # built now, children included
    zeros = lay.zero_values()
    assert lay.parse_construct(lay.build_construct(zeros)) == lay.parse(lay.build(zeros))


# -- single spec files through the cache (spec_file -> cache.cached_doc) -----------------------

def _doc_loader() -> tuple[list[Path], object]:
    calls: list[Path] = []

    def load(path: Path) -> dict[str, object]:
        calls.append(path)
        doc: dict[str, object] = yaml.load(path.read_text(), Loader=yaml.CSafeLoader)
        return doc

    return calls, load


def test_a_single_spec_file_is_read_from_the_cache_on_the_next_start(
    specs_copy: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("EYEQ_SPI_NO_CACHE", raising=False)
    monkeypatch.setattr(cache, "_DIGESTS", {})
    monkeypatch.setattr(cache, "KEEP_KEYS", 0)
    calls, load = _doc_loader()
    first = cache.cached_doc(specs_copy, "link.yaml", load)  # type: ignore[arg-type]
    second = cache.cached_doc(specs_copy, "link.yaml", load)  # type: ignore[arg-type]
    assert len(calls) == 1 and first == second == yaml.safe_load(
        (specs_copy / "link.yaml").read_text())
    (marshalled,) = (tmp_path / "cache").glob("doc-*-link.yaml.marshal")
    assert marshalled.stat().st_mode & 0o077 == 0

    path = specs_copy / "link.yaml"  # a new start after an edit: a new key, old file removed
    path.write_text(path.read_text() + "\nextra_key_for_the_test: 1\n")
    monkeypatch.setattr(cache, "_DIGESTS", {})
    third = cache.cached_doc(specs_copy, "link.yaml", load)  # type: ignore[arg-type]
    assert len(calls) == 2 and third["extra_key_for_the_test"] == 1
    assert len(list((tmp_path / "cache").glob("doc-*-link.yaml.marshal"))) == 1

    (marshalled,) = (tmp_path / "cache").glob("doc-*-link.yaml.marshal")
    marshalled.write_bytes(b"\xffnot marshal")  # corrupt: parsed again, never fatal
    monkeypatch.setattr(cache, "_DIGESTS", {})
    assert cache.cached_doc(specs_copy, "link.yaml", load) == third  # type: ignore[arg-type]
    assert len(calls) == 3


def test_a_doc_marshal_cannot_hold_is_returned_uncached(
    specs_copy: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import datetime

    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(cache, "_DIGESTS", {})
    calls: list[Path] = []

    def load(path: Path) -> dict[str, object]:
        calls.append(path)
        return {"when": datetime.date(2026, 1, 1)}  # YAML timestamps: marshal cannot hold them

    for _ in range(2):
        assert cache.cached_doc(specs_copy, "link.yaml", load)["when"].year == 2026
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


@pytest.mark.parametrize("argv", [
    ["demo", "--fatal", "999"], ["demo", "--stop-dasp", "FOO@3"], ["demo", "--sw", "7.7"],
    ["sim", "--listen", "tcp://127.0.0.1:0", "--drop-reply", "nosuch"],
    ["demo", "--boot-test-bits", "NOPE"], ["dissect", "--id", "obstacles", "SMALL_HEX"],
])
def test_a_usage_error_about_a_name_reads_the_names_index_not_the_catalogue(
    warm_cache: dict[str, str], argv: list[str]
) -> None:
    rc, mods = _imports(argv, warm_cache, ("eyeq_spi.catalog.messages", "pickle", *HEAVY))
    assert rc == 2 and mods == []


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


@pytest.mark.parametrize(("given", "expected"), [(None, "1"), ("3", "3")])
def test_the_cli_keeps_openblas_to_one_thread_unless_the_user_chose(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], given: str | None,
    expected: str,
) -> None:
    """numpy's OpenBLAS starts a spinning thread per core at import, which only burned CPU (no
    command does linear algebra): main() asks for one before anything imports numpy, and leaves
    a value the user set."""
    from eyeq_spi.cli import main

    if given is None:
        monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OPENBLAS_NUM_THREADS", given)
    assert main(["spec", "list"]) == 0
    capsys.readouterr()
    assert os.environ["OPENBLAS_NUM_THREADS"] == expected


_CONSOLE = (
    "import gc, io, json, sys, contextlib\n"
    "import eyeq_spi.cli.dissect as d\n"
    "finalized = []\n"
    "class Cycle:\n"
    "    def __del__(self):\n"
    "        finalized.append(1)\n"
    "real = d.run_dissect\n"
    "def run_dissect(args):\n"
    "    rc = real(args)\n"
    "    c = Cycle(); c.me = c  # garbage of the command, reachable only by the collector\n"
    "    del c\n"
    "    return rc\n"
    "d.run_dissect = run_dissect\n"
    "from eyeq_spi.cli import console\n"
    "sys.argv = ['eyeq-spi', *json.loads(sys.argv[1])]\n"
    "with contextlib.redirect_stdout(io.StringIO()):\n"
    "    rc = console()\n"
    "print(json.dumps([rc, len(finalized), gc.get_freeze_count(), len(gc.get_objects()),\n"
    "                  gc.isenabled()]))\n"
)


def test_the_console_entry_collects_the_commands_garbage_and_freezes_the_rest(
    warm_cache: dict[str, str]
) -> None:
    """``eyeq-spi`` (``cli.console``): after the command, its own garbage is collected (a cycle
    with a finalizer is finalized) and everything still alive is frozen, so that the exit's full
    collections do not walk the modules, catalogue and layouts again; ``main`` (a library call)
    unfreezes instead (the test above)."""
    import json
    import subprocess
    import sys

    argv = json.dumps(["dissect", warm_cache["BIG_PCAPNG"], "--stats"])
    out = subprocess.run([sys.executable, "-c", _CONSOLE, argv], env=warm_cache, check=True,
                         capture_output=True, text=True, timeout=120)
    rc, finalized, frozen, tracked, enabled = json.loads(out.stdout.strip().splitlines()[-1])
    assert (rc, finalized, enabled) == (0, 1, True)
    assert frozen > 20_000 and tracked < 100, (frozen, tracked)
