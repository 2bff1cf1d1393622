"""No module of the package is over 600 lines (docs/STYLE.md): a longer one is split along a seam
(as the host's bring-up sits beside its receive path, and the simulated EyeQ's MESP answers beside
its boot and DASP)."""

from __future__ import annotations

from pathlib import Path

import eyeq_spi

LIMIT = 600
PACKAGE = Path(eyeq_spi.__file__).parent


def test_no_module_is_over_600_lines() -> None:
    long = {p.relative_to(PACKAGE.parent).as_posix(): n for p in sorted(PACKAGE.rglob("*.py"))
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > LIMIT}
    assert long == {}, f"split these modules along a seam (limit {LIMIT} lines): {long}"
