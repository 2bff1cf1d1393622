"""What a user feels of a start: ``--help``, a usage error and the ``dissect`` of a small file
answer within their floors (CPU time of a fresh process), and ``--help`` or a usage error imports
no heavy library."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys

import pytest

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
QUICK = 0.1  # CPU-s: --help and usage errors
SMALL_DISSECT = 0.3  # CPU-s: dissect of a 20-transfer file

USAGE_ERRORS = [
    ["nonsense"],
    ["demo", "--fatal", "999"],
    ["demo", "--stop-dasp", "FOO@3"],
    ["demo", "--sw", "7.7"],
    ["host", "--port", "socket://127.0.0.1"],
    ["sim", "--listen", "tcp://127.0.0.1:0", "--drop-reply", "nosuch"],
    ["dissect", "--id", "zz", "SMALL_HEX"],
]


@pytest.fixture(scope="module")
def warm_cache(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """A filled catalogue cache (a user's first start parses specs/ once) and the first 20
    transfers of a demo run as a hex file."""
    d = tmp_path_factory.mktemp("startup")
    env = {**os.environ, "EYEQ_SPI_CACHE_DIR": str(d / "cache")}
    env.pop("EYEQ_SPI_NO_CACHE", None)
    demo = d / "demo.pcapng"
    subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "demo", "--virtual-time", "--duration",
                    "1", "--capture", str(demo)], env=env, check=True, capture_output=True,
                   timeout=120)
    from eyeq_spi.capture.pcapng_io import read_pcapng

    with demo.open("rb") as fh:
        records = [r for _, r in zip(range(20), read_pcapng(fh), strict=False)]
    small = d / "small.hex"
    small.write_text("".join(f"{r.time:.6f} {r.direction} {r.data.hex()}\n" for r in records))
    return {**env, "SMALL_HEX": str(small)}


def _argv(argv: list[str], env: dict[str, str]) -> list[str]:
    return [env.get(a, a) for a in argv]


def _cpu(argv: list[str], env: dict[str, str]) -> tuple[int, float]:
    """Exit code and CPU seconds (user + system) of ``eyeq-spi argv`` as a fresh process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    r = subprocess.run([sys.executable, "-m", "eyeq_spi.cli", *_argv(argv, env)], env=env,
                       capture_output=True, timeout=120, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.returncode, (after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)


@pytest.mark.realtime
@pytest.mark.parametrize(("argv", "rc", "floor"), [
    (["--help"], 0, QUICK),
    *[(argv, 2, QUICK) for argv in USAGE_ERRORS],
    (["dissect", "SMALL_HEX"], 0, SMALL_DISSECT),
    (["dissect", "SMALL_HEX", "--json"], 0, SMALL_DISSECT),
])
def test_a_quick_command_answers_within_its_floor(
    warm_cache: dict[str, str], argv: list[str], rc: int, floor: float
) -> None:
    """The best of three starts (a shared machine only ever adds time): tools/bench_startup.py
    gives the medians."""
    runs = [_cpu(argv, warm_cache) for _ in range(3)]
    assert {code for code, _ in runs} == {rc}
    assert min(cpu for _, cpu in runs) <= floor, (argv, runs)


def _imports(argv: list[str], env: dict[str, str], watch: tuple[str, ...]) -> tuple[int, list[str]]:
    cmd = [sys.executable, "-c", _PROBE, json.dumps(_argv(argv, env)), json.dumps(watch)]
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True, timeout=120)
    rc, mods = json.loads(out.stdout.strip().splitlines()[-1])
    return int(rc), list(mods)


@pytest.mark.parametrize(("argv", "rc"), [(["--help"], 0), *[(a, 2) for a in USAGE_ERRORS]])
def test_help_and_usage_errors_import_no_heavy_library(
    warm_cache: dict[str, str], argv: list[str], rc: int
) -> None:
    got_rc, mods = _imports(argv, warm_cache, HEAVY)
    assert (got_rc, mods) == (rc, []), argv


def test_the_probe_sees_a_heavy_import() -> None:
    """The guard above can fail: a command that needs yaml (no cache) is seen importing it."""
    env = {**os.environ, "EYEQ_SPI_NO_CACHE": "1"}
    rc, mods = _imports(["spec", "show", "0xE4"], env, HEAVY)
    assert rc == 0 and "yaml" in mods
