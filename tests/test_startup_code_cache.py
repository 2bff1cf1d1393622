"""The cache of generated code (``cache.compiled_code``): a class made from cached code is the
class dataclasses makes, a fast layout codec the codec its text makes, and a second start
compiles nothing."""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi.catalog import cache


def _make() -> list[type]:
    """Fresh classes of the kinds the package uses (frozen, slots, defaults, factories,
    ``__post_init__``, order)."""

    @dataclasses.dataclass(frozen=True, slots=True)
    class Event:
        num: int
        cause: str = "nak_limit"

        def __post_init__(self) -> None:
            if self.num < 0:
                raise ValueError("negative")

    @dataclasses.dataclass
    class Counters:
        frames: int = 0
        naks: dict[int, int] = dataclasses.field(default_factory=dict)
        note: str = dataclasses.field(default="", repr=False, compare=False)

    @dataclasses.dataclass(frozen=True, order=True)
    class Key:
        major: int
        minor: int = 0

    return [Event, Counters, Key]


def _behaviour(classes: list[type]) -> list[Any]:
    event, counters, key = classes
    out: list[Any] = []
    a, b = event(3), event(3, "peer_reset")
    out += [repr(a), a == event(3), a == b, hash(a) == hash(event(3)), a.__slots__]
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.num = 4
    with pytest.raises(ValueError, match="negative"):
        event(-1)
    c = counters()
    c.naks[1] = 2
    out += [repr(c), c == counters(naks={1: 2}, note="x"), counters().naks is not c.naks]
    out += [key(1) < key(1, 1), repr(sorted([key(9), key(8, 1)])), repr(key(8))]
    for cls in classes:  # the generated methods themselves: signatures and annotations
        init = vars(cls)["__init__"]
        out += [str(inspect.signature(cls)), init.__annotations__, init.__code__.co_filename,
                vars(cls)["__repr__"].__qualname__]
    return out


@pytest.fixture
def compiles(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The sources the cache compiles (a fresh cache directory)."""
    monkeypatch.setenv("EYEQ_SPI_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("EYEQ_SPI_NO_CACHE", raising=False)
    seen: list[str] = []
    real: Callable[..., Any] = compile

    def counting(source: str, *args: Any, **kw: Any) -> Any:
        seen.append(source)
        return real(source, *args, **kw)

    monkeypatch.setattr(cache, "compile", counting, raising=False)
    return seen


def test_classes_from_cached_code_are_the_classes_dataclasses_makes(
    compiles: list[str], tmp_path: Path
) -> None:
    plain = _behaviour(_make())
    with cache.compiled_code("test"):
        first = _behaviour(_make())
    assert compiles and not hasattr(dataclasses, "exec")
    (path,) = (tmp_path / "cache").glob("code-*-test.marshal")
    assert path.stat().st_mode & 0o077 == 0
    n = len(compiles)
    with cache.compiled_code("test"):  # the next start: all from the file
        second = _behaviour(_make())
    assert len(compiles) == n
    assert plain == first == second


def test_a_corrupt_or_disabled_code_cache_compiles_as_dataclasses_does(
    compiles: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    plain = _behaviour(_make())
    with cache.compiled_code("test"):
        _make()
    (path,) = (tmp_path / "cache").glob("code-*-test.marshal")
    import marshal

    texts = list(marshal.loads(path.read_bytes()))
    path.write_bytes(marshal.dumps(dict.fromkeys(texts, 1)))  # marshal, but no code in it
    n = len(compiles)
    with cache.compiled_code("test"):
        assert _behaviour(_make()) == plain
    assert len(compiles) > n
    path.write_bytes(b"\xffnot marshal")
    n = len(compiles)
    with cache.compiled_code("test"):
        assert _behaviour(_make()) == plain
    assert len(compiles) > n  # compiled again, and written afresh
    monkeypatch.setenv("EYEQ_SPI_NO_CACHE", "1")
    with cache.compiled_code("test"):
        assert not hasattr(dataclasses, "exec") and _behaviour(_make()) == plain


def test_a_fast_codec_from_cached_code_decodes_as_a_fresh_one(
    compiles: list[str], tmp_path: Path
) -> None:
    from eyeq_spi.catalog.messages import catalog
    from eyeq_spi.codec.layout import LayoutCache
    from eyeq_spi.codec.layout_fast import FastCodec

    cat = catalog()
    lay = LayoutCache(cat).get("EYEQ_VIS_OBSTACLES_MSG", cat.default_sw)
    payload = bytes(range(256)) * (lay.size // 256) + bytes(lay.size % 256)
    fresh = FastCodec(lay)
    plain, plain_bytes = fresh.decode(payload), fresh.encode(fresh.decode(payload))
    for _ in range(2):  # the first start compiles it, the next reads it
        n = len(compiles)
        with cache.compiled_code("test"):
            codec = FastCodec(lay)
        assert repr(codec.decode(payload)) == repr(plain)  # NaNs from the byte pattern too
        assert codec.encode(codec.decode(payload)) == plain_bytes
    assert len(compiles) == n
