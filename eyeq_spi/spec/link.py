"""``specs/link.yaml`` as typed defaults for the link, transport and stream layers."""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

import yaml

from eyeq_spi.errors import SpecError


def specs_dir() -> Path:
    """The ``specs/`` tree: shipped inside the package, or the repository's during development."""
    here = Path(__file__).resolve()
    for candidate in (here.parent.parent / "specs", here.parents[2] / "specs"):
        if (candidate / "link.yaml").is_file():
            return candidate
    raise SpecError("cannot find specs/ (looked beside the package and in the repository)")


@cache
def link_spec() -> dict[str, Any]:
    path = specs_dir() / "link.yaml"
    try:
        with path.open(encoding="utf-8") as fh:
            doc = yaml.safe_load(fh)
    except (OSError, yaml.YAMLError) as exc:
        raise SpecError(f"{path}: {exc}") from exc
    if not isinstance(doc, dict):
        raise SpecError(f"{path}: not a mapping")
    return doc
