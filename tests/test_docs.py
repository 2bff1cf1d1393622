"""The README and docs/ cannot drift from the program: every ``sh`` block they hold runs.

Each page's ``sh`` blocks run in order, as one bash script (``set -euo pipefail``), in a fresh
directory, with this Python's ``eyeq-spi`` first on PATH: a later block may use a file an
earlier one wrote, as a reader following the page would. Output examples are ``text`` blocks
and are not run. Processes a page starts in the background are stopped when it ends.

The README's two set-up commands are held elsewhere: the test command is what ``.ci/run`` runs
(checked here), and the install command's regular install (wheel, ``specs/`` inside, the
``eyeq-spi`` script) is built and started by ``tests/test_packaging.py``.
"""

from __future__ import annotations

import contextlib
import os
import re
import shlex
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCK = re.compile(r"^```(sh|bash)\n(.*?)^```", re.M | re.S)
SETUP = "python3 -m venv .venv"  # the README's two set-up commands start so
PAGE_TIMEOUT_S = 240


def shell_blocks(page: Path) -> list[str]:
    return [m.group(2) for m in BLOCK.finditer(page.read_text(encoding="utf-8"))]


def _runnable(page: Path) -> list[str]:
    return [b for b in shell_blocks(page) if not b.startswith(SETUP)]


def test_every_page_is_found_and_the_readme_has_its_two_setup_commands() -> None:
    setup = [b for b in shell_blocks(ROOT / "README.md") if b.startswith(SETUP)]
    assert len(setup) == 2, setup
    assert "eyeq-spi demo" in setup[0] and "tools/check.py" in setup[1]


def test_ci_runs_exactly_the_readme_test_command() -> None:
    test_cmd = [b for b in shell_blocks(ROOT / "README.md") if b.startswith(SETUP)][1].strip()
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert test_cmd in ci.splitlines(), (test_cmd, ci)


@pytest.mark.parametrize("page", [p for p in PAGES if _runnable(p)],
                         ids=lambda p: p.relative_to(ROOT).as_posix())
def test_shell_blocks_run(page: Path, tmp_path: Path) -> None:
    script = "set -euo pipefail\n" + "\n".join(_runnable(page))
    env = {**os.environ,
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           # a page that says "from a clone" may run the clone's own modules (python -m tests.x)
           "PYTHONPATH": str(ROOT),
           "HOME": str(tmp_path / "home"), "EYEQ_SPI_REPO": str(ROOT), "COLUMNS": "80",
           "LINES": "24", "NO_COLOR": "1"}
    proc = subprocess.Popen(["bash", "-c", script], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=PAGE_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        pytest.fail(f"{page.name}: its shell blocks ran over {PAGE_TIMEOUT_S} s\n{out[-4000:]}")
    finally:
        with contextlib.suppress(ProcessLookupError):  # what the page left in the background
            os.killpg(proc.pid, signal.SIGTERM)
    assert proc.returncode == 0, (
        f"{page.relative_to(ROOT)}: a shell block failed (exit {proc.returncode})\n"
        f"script:\n{script}\noutput (tail):\n{out[-4000:]}")


def test_the_harness_fails_a_failing_block(tmp_path: Path) -> None:
    """The runner above would report a page whose command fails (it is not a formality)."""
    page = tmp_path / "page.md"
    page.write_text("```sh\neyeq-spi dissect no-such-file.pcapng --stats\n```\n")
    script = "set -euo pipefail\n" + "\n".join(_runnable(page))
    env = {**os.environ,
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    rc = subprocess.call(["bash", "-c", script], cwd=tmp_path, env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    assert rc != 0, shlex.quote(script)
