#!/usr/bin/env python3
"""Run every check CI runs: tshark and sigrok-cli (installed if missing), ruff, mypy --strict,
the import-layer contract, the specs schema, then pytest. Exits non-zero on the first failure;
pytest's exit code 5 (no tests collected) is a failure too."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run(name: str, cmd: list[str]) -> int:
    print(f"==> {name}: {' '.join(cmd)}", flush=True)
    return subprocess.call(cmd, cwd=ROOT)


def ensure_tshark() -> None:
    """The Wireshark agreement tests need Debian's tshark: install it when it is missing and we
    may (root with apt-get, as in CI); otherwise those tests skip and say why."""
    if shutil.which("tshark"):
        return
    if shutil.which("apt-get") is None or not hasattr(os, "geteuid") or os.geteuid() != 0:
        print("==> tshark missing and cannot be installed here: its tests will be skipped")
        return
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    print("==> installing tshark (apt-get)", flush=True)
    subprocess.call(["apt-get", "update", "-qq"], env=env)
    subprocess.call(["apt-get", "install", "-y", "-qq", "tshark"], env=env)


def ensure_sigrok() -> None:
    """The sigrok decoder test (tests/test_bench_sigrok.py) runs Debian's sigrok-cli with its
    libsigrokdecode (package libsigrokdecode4, pulled in by sigrok-cli): installed like tshark;
    otherwise that test skips and says why."""
    if shutil.which("sigrok-cli"):
        return
    if shutil.which("apt-get") is None or not hasattr(os, "geteuid") or os.geteuid() != 0:
        print("==> sigrok-cli missing and cannot be installed here: its tests will be skipped")
        return
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    print("==> installing sigrok-cli and libsigrokdecode4 (apt-get)", flush=True)
    subprocess.call(["apt-get", "update", "-qq"], env=env)
    subprocess.call(["apt-get", "install", "-y", "-qq", "sigrok-cli", "libsigrokdecode4"],
                    env=env)


def main() -> int:
    ensure_tshark()
    ensure_sigrok()
    py = sys.executable
    steps: list[tuple[str, list[str]]] = [
        ("ruff", [py, "-m", "ruff", "check", "eyeq_spi", "tests", "tools"]),
        ("mypy", [py, "-m", "mypy"]),
        ("import layers", [shutil.which("lint-imports") or "lint-imports"]),
        ("specs schema", [py, "-m", "eyeq_spi.spec.schema", "specs"]),
    ]
    for name, cmd in steps:
        if run(name, cmd) != 0:
            print(f"FAILED: {name}", file=sys.stderr)
            return 1
    rc = run("pytest", [py, "-m", "pytest", *sys.argv[1:]])
    if rc == 5:
        print("FAILED: pytest collected no tests", file=sys.stderr)
        return 1
    return rc


if __name__ == "__main__":
    sys.exit(main())
