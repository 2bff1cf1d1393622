"""Loading single files of ``specs/``: ``link.yaml`` gives the defaults of the link, transport
and stream layers; other files (``flash_map.yaml``) are read the same way."""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

from eyeq_spi.errors import SpecError


def specs_dir() -> Path:
    """The ``specs/`` tree: shipped inside the package, or the repository's during development."""
    here = Path(__file__).resolve()
    for candidate in (here.parent.parent / "specs", here.parents[2] / "specs"):
        if (candidate / "link.yaml").is_file():
            return candidate
    raise SpecError("cannot find specs/ (looked beside the package and in the repository)")


def link_spec() -> dict[str, Any]:
    return spec_file("link.yaml")


@cache
def spec_file(name: str) -> dict[str, Any]:
    """One YAML file of ``specs/`` as a mapping (cached in the process, and across starts by
    :func:`eyeq_spi.catalog.cache.cached_data`)."""
    from eyeq_spi.catalog.cache import cached_data

    root = specs_dir()
    return cached_data(root, name, lambda: load_file(root / name))


def load_file(path: Path) -> dict[str, Any]:
    """Parse one YAML file of ``specs/`` (libyaml) into a mapping; SpecError if it is not one."""
    import yaml  # here, not at module level: a start from the cache never parses YAML

    try:
        with path.open(encoding="utf-8") as fh:
            doc = yaml.load(fh, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise SpecError(f"{path}: {exc}") from exc
    if not isinstance(doc, dict):
        raise SpecError(f"{path}: not a mapping")
    return doc


def is_number(value: Any) -> bool:
    """An int or a float, not a bool (YAML's ``true`` is an int to Python)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)
