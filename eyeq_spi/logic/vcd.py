"""VCD waveforms of the SPI lines (as sigrok, PulseView and simulators write them), decoded into
chip-select transfers, streamed in bounded memory.

Signals are found by name: ``<channel>_cs``, ``_clk``, ``_mosi``, ``_miso`` (``specs/bench.yaml``
``vcd.name_format``; ``h2e_cs``...), plain ``cs``/``clk``/``mosi``/``miso`` for a single channel,
or given with ``--signals CHANNEL=CS,CLK,MOSI[,MISO]``. Bits are sampled on the clock edge of the
SPI mode (1 by default: the falling edge, §6 frameFormat POLARITY_0_PHASE_1) while chip select is
low; a transfer runs from CS falling to CS rising and is stamped with the falling edge's time.
``x``/``z`` values leave a line as it was. A transfer still open at the end of the file was cut
by the capture and is dropped.
"""

from __future__ import annotations

import re
from collections.abc import Iterator

from eyeq_spi.capture.pcapng_io import Readable, Transfer
from eyeq_spi.errors import InputError
from eyeq_spi.logic.options import (
    MAX_TRANSFER,
    SIGNALS,
    Route,
    SpiOptions,
    sample_on_rising,
    whole_chunks,
)

MAX_HEADER = 16 << 20
_UNITS = {b"s": 1.0, b"ms": 1e-3, b"us": 1e-6, b"ns": 1e-9, b"ps": 1e-12, b"fs": 1e-15}
_ALIASES = {"cs": "cs", "ncs": "cs", "csn": "cs", "cs_n": "cs", "ss": "cs", "nss": "cs",
            "clk": "clk", "sck": "clk", "sclk": "clk", "mosi": "mosi", "miso": "miso"}
_NAME = re.compile(r"^(?P<channel>.*?)[_.](?P<signal>" + "|".join(_ALIASES) + r")$", re.I)


CLK, MOSI, MISO = range(1, 4)  # a signal's SPI role (0: CS)


class Chan:
    """One SPI channel: its line levels, the transfer being shifted in, its routes."""

    __slots__ = ("active", "clk", "cs", "mi", "miso", "miso_bytes", "mo", "mosi", "mosi_bytes",
                 "name", "nbits", "routes", "t0")

    def __init__(self, name: str, routes: list[Route]) -> None:
        self.name = name
        self.routes = routes
        self.cs = 1
        self.clk = -1
        self.mosi = self.miso = 0
        self.active = False
        self.nbits = self.mo = self.mi = 0
        self.mosi_bytes = bytearray()
        self.miso_bytes = bytearray()
        self.t0 = 0

    def emit(self, time: float) -> Iterator[Transfer]:
        for route in self.routes:
            data = self.mosi_bytes if route.line == "mosi" else self.miso_bytes
            yield Transfer(time, route.direction, bytes(data))


def _skip_meta(head: bytes) -> bytes:
    """sigrok-cli 0.7, converting a file (not recording from a device), writes its input's
    ``META samplerate: N`` line before the VCD itself; it is not VCD and is skipped."""
    while head.startswith(b"META ") and b"\n" in head:
        head = head.split(b"\n", 1)[1]
    return head


def sniff(head: bytes) -> str | None:
    text = _skip_meta(head.lstrip())
    if text[:1] == b"$" and re.match(rb"\$(date|version|timescale|comment|scope|var)\b", text):
        return "vcd"
    return None


def _header(tokens: Iterator[bytes]) -> tuple[float, list[tuple[str, bytes, str]]]:
    """(seconds per tick, [(scope path, id, reference)]) up to ``$enddefinitions $end``."""
    scale = 1e-9
    scopes: list[str] = []
    vars_: list[tuple[str, bytes, str]] = []
    for tok in tokens:  # read_vcd bounds the header's size
        body: list[bytes] = []
        for token in tokens:
            if token == b"$end":
                break
            body.append(token)
        else:
            break
        if tok == b"$enddefinitions":
            return scale, vars_
        if tok == b"$timescale":
            match = re.fullmatch(rb"(1|10|100)\s*(s|ms|us|ns|ps|fs)", b"".join(body))
            if match is None:
                raise InputError(f"bad VCD timescale {b' '.join(body)[:30]!r}")
            scale = int(match.group(1)) * _UNITS[match.group(2)]
        elif tok == b"$scope":
            scopes.append(body[-1].decode("utf-8", "replace") if body else "")
        elif tok == b"$upscope":
            if scopes:
                scopes.pop()
        elif tok == b"$var":
            if len(body) < 4:
                raise InputError(f"bad VCD $var: {b' '.join(body)[:40]!r}")
            vars_.append((".".join(scopes), body[2], body[3].decode("utf-8", "replace")))
        elif not tok.startswith(b"$"):
            raise InputError(f"not a VCD file: unexpected {tok[:20]!r} in the header")
    raise InputError("truncated VCD: no $enddefinitions")


def _channels(vars_: list[tuple[str, bytes, str]], opts: SpiOptions
              ) -> dict[bytes, list[tuple[Chan, int]]]:
    found: dict[str, dict[str, bytes]] = {}
    if opts.signals:
        by_name: dict[str, bytes] = {}
        for scope, ident, ref in vars_:
            by_name.setdefault(ref.lower(), ident)
            by_name.setdefault(f"{scope}.{ref}".lower(), ident)
        for chan, names in opts.signals.items():
            sigs: dict[str, bytes] = {}
            for sig, name in zip(SIGNALS, names, strict=True):
                if name is None:
                    continue
                if name.lower() not in by_name:
                    raise InputError(f"--signals: no VCD signal named {name!r}")
                sigs[sig] = by_name[name.lower()]
            found[chan] = sigs
    else:
        for scope, ident, ref in vars_:
            match = _NAME.match(ref)
            if match is not None:
                chan, sig = match.group("channel"), _ALIASES[match.group("signal").lower()]
            elif ref.lower() in _ALIASES:
                leaf = scope.rsplit(".", 1)[-1]
                chan = leaf if any(d in leaf.lower() for d in ("h2e", "e2h")) else ""
                sig = _ALIASES[ref.lower()]
            else:
                continue
            found.setdefault(chan, {}).setdefault(sig, ident)
    found = {c: s for c, s in found.items() if "cs" in s or "clk" in s}
    if not found:
        raise InputError("no SPI signals in the VCD: name them <channel>_cs, _clk, _mosi, "
                         "_miso or give --signals CHANNEL=CS,CLK,MOSI[,MISO]")
    table: dict[bytes, list[tuple[Chan, int]]] = {}
    for name, sigs in found.items():
        ch = Chan(name, opts.routes(name, len(found)))
        if not ch.routes:
            continue
        need = {"cs", "clk"} | {r.line for r in ch.routes}
        missing = sorted(need - set(sigs))
        if missing:
            label = name or "the capture"
            raise InputError(f"VCD channel {label!r} has no {', '.join(missing)} signal "
                             "(a transfer is framed by chip select)")
        for sig, ident in sigs.items():
            table.setdefault(ident, []).append((ch, SIGNALS.index(sig)))
    if not table:
        raise InputError("no VCD channel is mapped to h2e or e2h (see --channel-map)")
    return table


def read_vcd(src: Readable, opts: SpiOptions, *, chunk_size: int = 1 << 20
             ) -> Iterator[Transfer]:
    """Value changes -> one transfer per chip-select frame and direction."""
    chunks = whole_chunks(src, chunk_size, b"\n \t\r", MAX_HEADER, "VCD token longer than 16 MiB")
    head = b""
    for chunk in chunks:
        head += chunk
        match = re.search(rb"\$enddefinitions\s+\$end\s", head)
        if match is not None:
            break
        if len(head) > MAX_HEADER:
            raise InputError("VCD header longer than 16 MiB")
    else:
        match = re.search(rb"\$enddefinitions\s+\$end", head)
    if match is None:
        if not head.lstrip()[:1] == b"$":  # a VCD starts with a $ keyword ($date, $timescale..)
            raise InputError("not a VCD file: it does not start with a $ keyword")
        raise InputError("truncated VCD: no $enddefinitions")
    # a META line only before the definitions end
    definitions = _skip_meta(head[:match.start()]) + head[match.start():match.end()]
    scale, vars_ = _header(iter(definitions.split()))
    table = _channels(vars_, opts)
    reader = _Reader(table, scale, opts)
    yield from reader.feed(head[match.end():])
    for chunk in chunks:
        yield from reader.feed(chunk)


class _Reader:
    """Value changes -> transfers: a loop over the tokens, each channel's state in its
    :class:`Chan`, carried from chunk to chunk."""

    def __init__(self, table: dict[bytes, list[tuple[Chan, int]]], scale: float,
                 opts: SpiOptions) -> None:
        self.table = table
        self.scale = scale
        self.sample_level = 1 if sample_on_rising(opts.mode) else 0
        self.msb = opts.bit_order == "msb_first"
        self.tick = 0
        self.vector_value: int | None = None
        self.in_comment = False

    def feed(self, chunk: bytes) -> Iterator[Transfer]:
        yield from self._tokens(chunk.split())

    def _tokens(self, batch: list[bytes]) -> Iterator[Transfer]:
        table, scale, msb = self.table, self.scale, self.msb
        sample_level = self.sample_level
        tick = self.tick
        vector_value = self.vector_value
        in_comment = self.in_comment
        try:
            for tok in batch:
                c0 = tok[0]
                if vector_value is not None:
                    ident, level = tok, vector_value
                    vector_value = None
                elif c0 == 35:  # '#'
                    try:
                        tick = int(tok[1:])
                    except ValueError:
                        raise InputError(f"bad VCD time {tok[:20]!r}") from None
                    continue
                elif c0 == 48 or c0 == 49:  # '0' '1'
                    ident, level = tok[1:], c0 - 48
                elif c0 == 36:  # '$'
                    if tok == b"$comment":
                        in_comment = True
                    elif tok == b"$end":
                        in_comment = False
                    continue
                elif in_comment or c0 in b"xXzZ":
                    continue
                elif c0 in b"bB":
                    bits = tok[1:].replace(b"x", b"0").replace(b"z", b"0").replace(b"X", b"0")
                    vector_value = bits[-1] - 48 if bits else 0
                    continue
                elif c0 in b"rR":
                    vector_value = -1
                    continue
                else:
                    raise InputError(f"not a VCD value change: {tok[:20]!r}")
                targets = table.get(ident)
                if targets is None or level < 0:
                    continue
                for ch, role in targets:
                    if role == CLK:
                        if level == ch.clk:
                            continue
                        ch.clk = level
                        if level != sample_level or not ch.active:
                            continue
                        if msb:
                            ch.mo = (ch.mo << 1) | ch.mosi
                            ch.mi = (ch.mi << 1) | ch.miso
                        else:
                            ch.mo |= ch.mosi << ch.nbits
                            ch.mi |= ch.miso << ch.nbits
                        ch.nbits += 1
                        if ch.nbits == 8:
                            ch.mosi_bytes.append(ch.mo)
                            ch.miso_bytes.append(ch.mi)
                            ch.nbits = ch.mo = ch.mi = 0
                            if len(ch.mosi_bytes) > MAX_TRANSFER:
                                raise InputError(f"transfer longer than {MAX_TRANSFER} "
                                                 "bytes (chip select never rises?)")
                    elif role == MOSI:
                        ch.mosi = level
                    elif role == MISO:
                        ch.miso = level
                    elif level != ch.cs:
                        ch.cs = level
                        if level == 0:
                            ch.active = True
                            ch.t0 = tick
                            ch.nbits = ch.mo = ch.mi = 0
                            ch.mosi_bytes.clear()
                            ch.miso_bytes.clear()
                        elif ch.active:
                            ch.active = False
                            yield from ch.emit(ch.t0 * scale)
        finally:
            self.tick, self.vector_value, self.in_comment = tick, vector_value, in_comment
