"""Argument types shared by every subcommand: each turns one option's text into a checked
value or raises :class:`argparse.ArgumentTypeError` with the accepted range or values, so the CLI
exits 2 before any work starts. Names from ``specs/`` match in any case, by hex ID too, with
"did you mean"; the catalogue is loaded only when an option needs it.
"""

from __future__ import annotations

import argparse
import math
import os
import re
from collections.abc import Callable, Iterable
from typing import Any, NoReturn

from eyeq_spi.errors import AdapterError, EyeqError

Type = Callable[[str], Any]


def _bad(message: str) -> NoReturn:
    raise argparse.ArgumentTypeError(message)


def catalogue() -> Any:
    from eyeq_spi.catalog.messages import catalog

    try:
        return catalog()
    except EyeqError as exc:  # a broken specs/ is not the user's argument: say so plainly
        _bad(f"cannot check it: {exc}")


_INDEX_TAG = "argument-names-1"  # bump when _build_index changes shape


def _index() -> dict[str, Any]:
    """The names and IDs the argument checks need, as plain data cached beside the catalogue
    (``marshal``, keyed on ``specs/`` like it): checking a name, and so every usage error,
    neither imports nor unpickles the catalogue."""
    from eyeq_spi.catalog.cache import cached_data
    from eyeq_spi.catalog.link import specs_dir

    try:
        return cached_data(specs_dir(), _INDEX_TAG, _build_index)
    except EyeqError as exc:  # a broken specs/ is not the user's argument: say so plainly
        _bad(f"cannot check it: {exc}")


def _build_index() -> dict[str, Any]:
    cat = catalogue()
    return {
        "sw_versions": list(cat.sw_versions), "default_sw": cat.default_sw,
        "messages": [[m.name, m.data_id, m.protocol, m.direction] for m in cat.messages],
        "mesp": [[f.name, f.service, f.function] for f in cat.mesp],
        "enums": {n: {k: v.name for k, v in cat.enums[n].values.items()}
                  for n in ("fatal_error", "boot_test_result")},
    }


def did_you_mean(word: str, candidates: Iterable[str]) -> str:
    """`` (did you mean X?)`` for the closest candidates, case-insensitively, or ``""``."""
    import difflib

    by_upper = {c.upper(): c for c in candidates}
    wanted = word.strip().upper()
    close = [c for c in by_upper if wanted and wanted in c][:3] if len(wanted) >= 3 else []
    if not close:
        close = difflib.get_close_matches(wanted, list(by_upper), n=3, cutoff=0.6)
    if not close:
        return ""
    return f" (did you mean {' or '.join(by_upper[c] for c in close)}?)"


def _int(text: str) -> int:
    """Decimal, ``0x`` hex, ``0b`` or ``0o``; ``_`` separators allowed as in Python."""
    return int(text.strip(), 0)


# -- numbers -------------------------------------------------------------------------------------

def number(lo: float, hi: float, *, lo_open: bool = False, unit: str = "") -> Type:
    """A finite float in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``)."""
    span = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]{' ' + unit if unit else ''}"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            _bad(f"must be a number in {span}, got {text!r}")
        if not math.isfinite(value) or value < lo or value > hi or (lo_open and value == lo):
            _bad(f"must be a number in {span}, got {text!r}")
        return value

    parse.__name__ = "number"
    return parse


def integer(lo: int, hi: int, *, what: str = "an integer") -> Type:
    """An integer in ``lo..hi`` (decimal or ``0x`` hex)."""

    def parse(text: str) -> int:
        try:
            value = _int(text)
        except ValueError:
            _bad(f"must be {what} in {lo}..{hi}, got {text!r}")
        if not lo <= value <= hi:
            _bad(f"must be {what} in {lo}..{hi}, got {text!r}")
        return value

    parse.__name__ = "integer"
    return parse


# -- names from specs/ ---------------------------------------------------------------------------

def sw_release(text: str) -> str:
    """A SW release that ``specs/`` describes (``9.0``, ``8.1``, ``SW8_1``) -> its key."""
    from eyeq_spi.catalog.schema import normalise_sw

    idx = _index()
    releases = {k: k[2:].replace("_", ".") if "_" in k else f"{k[2:]}.0"
                for k in idx["sw_versions"]}
    try:
        key = normalise_sw(text, idx["default_sw"])
    except EyeqError:
        key = ""
    if key not in releases:
        _bad(f"unknown SW release {text!r}; specs/ has {', '.join(releases.values())}")
    return str(key)


def _named(text: str, entries: dict[str, Any], ids: dict[int, str], what: str,
           listing: str) -> str:
    """The entry named ``text`` (any case) or with the numeric ID ``text``."""
    stripped = text.strip()
    by_upper = {n.upper(): n for n in entries}
    if stripped.upper() in by_upper:
        return by_upper[stripped.upper()]
    try:
        ident = _int(stripped)
    except ValueError:
        ident = None
    if ident is not None:
        if ident in ids:
            return ids[ident]
        _bad(f"no {what} with ID {stripped}; {listing}")
    _bad(f"unknown {what} {stripped!r}{did_you_mean(stripped, entries)}; {listing}")


def _messages(protocol: str | None = None, direction: str | None = None
              ) -> tuple[dict[str, int], dict[int, str]]:
    """Name -> data ID and data ID -> name of the messages of ``protocol`` and ``direction``."""
    rows = [(name, data_id) for name, data_id, proto, way in _index()["messages"]
            if protocol in (None, proto) and direction in (None, way)]
    return dict(rows), {data_id: name for name, data_id in rows}


def eyeq_dasp_message(text: str) -> str:
    """A DASP message the EyeQ sends: name (any case) or data ID (``0xE4``) -> name."""
    names, ids = _messages("DASP", "e2h")
    return _named(text, names, ids, "DASP message of the EyeQ",
                  "eyeq-spi spec list shows them")


def message_id(text: str) -> int:
    """A data ID (0..255, ``0xE4``) or a message name (any case) -> its data ID."""
    names, ids = _messages()
    try:
        value = _int(text)
    except ValueError:
        return names[_named(text, names, ids, "message", "eyeq-spi spec list shows them")]
    if not 0 <= value <= 0xFF:
        _bad(f"must be a data ID in 0..255 (0x00..0xFF) or a message name, got {text!r}")
    return value


def mesp_function(text: str) -> str:
    """A MESP function: name (any case), ``SERVICE/FUNCTION`` (``0x05/0x04``) or a function
    number that only one service uses -> its name."""
    fns = {name: (service, function) for name, service, function in _index()["mesp"]}
    listing = "functions: " + ", ".join(fns)
    pair = re.fullmatch(r"\s*(\w+)\s*/\s*(\w+)\s*", text)
    if pair:
        try:
            key = (_int(pair.group(1)), _int(pair.group(2)))
        except ValueError:
            key = None
        for name, numbers in fns.items():
            if numbers == key:
                return str(name)
        _bad(f"no MESP function {text.strip()}; {listing}")
    by_fn: dict[int, list[str]] = {}
    for name, (_, function) in fns.items():
        by_fn.setdefault(function, []).append(name)
    unique = {k: v[0] for k, v in by_fn.items() if len(v) == 1}
    return _named(text, fns, unique, "MESP function", listing)


def count_suffix(base: Type, sep: str, what: str, default: str, suffix: Type) -> Type:
    """``NAME[{sep}VALUE]`` -> ``(base(NAME), suffix(VALUE))``."""

    def parse(text: str) -> tuple[Any, Any]:
        name, found, rest = text.partition(sep)
        if found and not rest:
            _bad(f"{text!r}: nothing after {sep!r} (expected {what})")
        try:
            value = suffix(rest if found else default)
        except argparse.ArgumentTypeError as exc:
            _bad(f"{what} of {text!r} {exc}")
        return base(name), value

    parse.__name__ = "pair"
    return parse


drop_reply = count_suffix(mesp_function, ":", "N", "1", integer(1, 1_000_000))
drop_reply.__doc__ = "``FUNCTION[:N]``: drop the first N (1..1000000) replies."
stop_dasp = count_suffix(eyeq_dasp_message, "@", "T", "0",
                         number(0, 86_400, unit="s"))
stop_dasp.__doc__ = "``MESSAGE[@T]``: stop sending the message at T s (default 0)."


def fatal_code(text: str) -> int:
    """A Fatal_Error of 0x41 (§7.1.5.2, enum ``fatal_error``): name (any case) or number."""
    values: dict[int, str] = _index()["enums"]["fatal_error"]
    ids = {k: n for k, n in values.items() if k != 0}
    names = {n: k for k, n in ids.items()}
    codes = ", ".join(f"{k}" for k in sorted(ids))
    name = _named(text, names, ids, "Fatal_Error code",
                  f"codes: {codes} (eyeq-spi spec show fatal_error names them)")
    return int(names[name])


def boot_test_bits(text: str) -> int:
    """TestResults of a failing boot (§7.1.5.3): an integer 1..0xFFFF or bit names joined with
    ``|`` or ``,`` (enum ``boot_test_result``)."""
    values: dict[int, str] = _index()["enums"]["boot_test_result"]
    bits = {n: 1 << k for k, n in values.items()}
    try:
        value = _int(text)
    except ValueError:
        value = 0
        for part in re.split(r"[|,+]", text):
            name = _named(part, bits, {}, "TestResults bit", "bits: " + ", ".join(bits))
            value |= bits[name]
    if not 1 <= value <= 0xFFFF:
        _bad(f"must be TestResults bits in 0x0001..0xFFFF or bit names, got {text!r}")
    return value


def regex(text: str) -> str:
    try:
        re.compile(text)
    except re.error as exc:
        _bad(f"bad regular expression {text!r}: {exc}")
    return text


# -- files and endpoints -------------------------------------------------------------------------

def input_file(text: str) -> str:
    """An existing readable file, or ``-`` for stdin."""
    if text == "-":
        return text
    if not os.path.exists(text):
        _bad(f"no such file: {text}")
    if os.path.isdir(text):
        _bad(f"{text} is a directory, not a file")
    if not os.access(text, os.R_OK):
        _bad(f"cannot read {text}: permission denied")
    return text


def output_file(text: str) -> str:
    """A file we can create or overwrite (its directory must exist)."""
    if not text:
        _bad("empty file name")
    if os.path.isdir(text):
        _bad(f"{text} is a directory, not a file")
    parent = os.path.dirname(os.path.abspath(text))
    if not os.path.isdir(parent):
        _bad(f"directory {parent} does not exist")
    if not os.access(parent, os.W_OK) or (os.path.exists(text) and not os.access(text, os.W_OK)):
        _bad(f"cannot write {text}: permission denied")
    return text


def output_dir(text: str) -> str:
    """A directory that exists or can be created in an existing directory."""
    if os.path.exists(text) and not os.path.isdir(text):
        _bad(f"{text} exists and is not a directory")
    parent = os.path.dirname(os.path.abspath(text))
    if not os.path.isdir(text) and not os.path.isdir(parent):
        _bad(f"directory {parent} does not exist")
    return text


def connect_address(text: str) -> str:
    """``--port URL`` of a command that connects, in the grammar of :mod:`eyeq_spi.phy.address`
    -> the URL to open; ``loop://`` has no peer on it: refused."""
    from eyeq_spi.phy.address import CONNECT_FORMS, is_spi, parse_connect

    if is_spi(text):
        return spi_side(text)
    if text.startswith("loop://"):
        _bad(f"loop:// echoes our own transfers back and has no peer on it; give {CONNECT_FORMS}")
    try:
        addr = parse_connect(text)
    except AdapterError as exc:
        _bad(str(exc))
    if "://" in addr.url and not addr.url.startswith(("socket://", "rfc2217://")):
        _bad(f"unsupported scheme {text.split('://', 1)[0]}://; give {CONNECT_FORMS}")
    return addr.url


def spi_side(text: str) -> str:
    """One side on SPI lines (``MASTER_URL,SLAVE_URL`` or a bench file), checked now (the
    devices are opened by the command)."""
    from eyeq_spi.phy.bench import parse_side

    try:
        parse_side(text)
    except EyeqError as exc:
        _bad(str(exc))
    return text


class Endpoint(argparse.Action):
    """``--listen``, ``--port`` and ``--pty`` of a command that may listen: each sets its own
    attribute (``listen``, ``port`` or ``pty``) in the namespace."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        from eyeq_spi.phy.address import is_spi, parse_listen

        if option_string == "--pty":
            namespace.pty = True
            return
        text = str(values)
        try:
            if option_string == "--listen" and is_spi(text):
                namespace.listen = spi_side(text)  # our slave channel waits on the lines
            elif option_string == "--listen":
                namespace.listen = parse_listen(text).url
            else:
                namespace.port = connect_address(text)
        except (AdapterError, argparse.ArgumentTypeError) as exc:
            raise argparse.ArgumentError(self, str(exc)) from None


def add_endpoints(parser: Any, group: Any, **helps: str) -> None:
    """``--listen``, ``--port`` and ``--pty`` (those given a help, in that order) in ``group``,
    through :class:`Endpoint`; each is None (``pty`` False) when not given."""
    for name, text in helps.items():
        shape: dict[str, Any] = ({"nargs": 0} if name == "pty" else
                                 {"metavar": "tcp://HOST:PORT" if name == "listen" else "URL"})
        group.add_argument(f"--{name}", dest="endpoint", action=Endpoint, help=text, **shape)
    parser.set_defaults(listen=None, port=None, pty=False)


def spec_entry(query: str) -> str:
    """``spec show``'s NAME: an exact name in any case, a data ID (``0xE4``: DASP, 0x41, 0x10;
    init messages by ID too), ``SERVICE/FUNCTION`` of a MESP function, or a unique part of a
    name (messages first, then init messages, MESP functions, structs, enums)."""
    cat = catalogue()
    kinds: list[list[str]] = [list(dict.fromkeys(names)) for names in (
        [m.name for m in cat.messages], list(cat.init_messages), [f.name for f in cat.mesp],
        list(cat.structs), list(cat.enums),
    )]
    stripped = query.strip()
    every = [n for names in kinds for n in names]
    exact = [n for n in every if n.upper() == stripped.upper()]
    if exact:
        return exact[0]
    pair = re.fullmatch(r"(\w+)\s*/\s*(\w+)", stripped)
    try:
        if pair:
            key = (_int(pair.group(1)), _int(pair.group(2)))
            for entry in cat.mesp:
                if (entry.service, entry.function) == key:
                    return str(entry.name)
            _bad(f"no MESP function {stripped}; eyeq-spi spec list shows them")
        ident = _int(stripped)
    except ValueError:
        ident = None
    if ident is not None:
        hits = [m.name for m in cat.messages if m.data_id == ident]
        hits += [n for n, im in cat.init_messages.items() if im.id == ident]
        if hits:
            return str(hits[0])
        _bad(f"no message or init message with ID {stripped}; eyeq-spi spec list shows them")
    for names in kinds:
        part = [n for n in names if stripped.upper() in n.upper()]
        if len(part) == 1:
            return part[0]
        if part:
            more = "" if len(part) <= 8 else f" and {len(part) - 8} more"
            _bad(f"{stripped!r} matches {', '.join(part[:8])}{more}: give more of the name")
    _bad(f"no message, struct, init message, MESP function or enum named {stripped!r}"
         f"{did_you_mean(stripped, every)}; eyeq-spi spec list shows them")


def one_line(message: str) -> str:
    """Collapse a message onto one line (argparse and OS messages can span several)."""
    return " ".join(message.split())
