"""The frame CRC of the Lua dissector (decision L3), unrolled per coverage of ``specs/link.yaml``.

A CRC without reflection is linear: over a covered stream of L bytes
``crc = K xor P[0][b0] xor ... xor P[L-1][b(L-1)]``, where ``P[i][b]`` is what byte ``b`` at
position ``i`` contributes and ``K`` what the initial value (and the final xor) contribute. The
tables are built once when the dissector loads; per frame the CRC is then one table look-up per
byte and a few calls of ``bit.bxor`` with many arguments, instead of five bit operations per
byte. The byte-wise CRC checks the check value of ``specs/link.yaml`` and the unrolled functions
at load.
"""

from __future__ import annotations

# bytes fetched by one string.byte call (one bxor call each): fewer calls cost less, and 64
# values plus the bxor call's 65 arguments stay well inside Lua 5.2's 250 registers
CHUNK = 64
# the bytes the dissector reads first (header word, CRC, transport type and argument) and
# passes in as h1..h8; the CRC reads the rest from ``tail``, the frame from byte HEAD on
HEAD = 8
# A frame whose bytes from SHORT on are all zero (a short message, a chunk of a payload's
# unused slots: a third of the DATA frames of a full-load capture) needs only its first SHORT.
SHORT = 32


def _segments(ranges: list[tuple[int, int]]) -> list[tuple[int, int, int]]:
    """(start, end, position in the covered stream) of each range."""
    out, pos = [], 0
    for start, stop in ranges:
        out.append((start, stop, pos))
        pos += stop - start
    return out


def _blocks(segments: list[tuple[int, int, int]], limit: int, indent: str) -> list[str]:
    """Lua adding the contributions of the covered bytes before ``limit`` (0-based): bytes
    below HEAD from the arguments h1..h8, the rest CHUNK bytes per string.byte call on
    ``tail``."""
    lines = []
    for seg_start, seg_end, pos in segments:
        start, seg_end = seg_start, min(seg_end, limit)
        while start < seg_end:
            if start < HEAD:  # bytes the caller passes
                end = min(seg_end, HEAD)
                terms = [f"P[h{start + i} + {(pos + start - seg_start + i - 1) * 256 + 1}]"
                         for i in range(1, end - start + 1)]
                lines.append(f"{indent}acc = bxor(acc, {', '.join(terms)})")
            else:
                end = min(seg_end, start + CHUNK)
                names = [f"b{i}" for i in range(1, end - start + 1)]
                terms = [f"P[b{i} + {(pos + start - seg_start + i - 1) * 256 + 1}]"
                         for i in range(1, end - start + 1)]
                lines += [f"{indent}do",
                          f"{indent}  local {', '.join(names)} = "
                          f"sbyte(tail, {start - HEAD + 1}, {end - HEAD})",
                          f"{indent}  acc = bxor(acc, {', '.join(terms)})",
                          f"{indent}end"]
            start = end
    return lines


def _function(name: str, ranges: list[tuple[int, int]]) -> list[str]:
    """``local function <name>(tail, h1, ..., h8)``: the CRC over ``ranges`` (0-based, end
    exclusive) of a frame whose first HEAD bytes the caller has already read and passes as
    ``h1..h8``, and whose bytes from HEAD on are the string ``tail`` (nil where the CRC covers
    none of them). A zero byte contributes nothing, so a frame whose bytes from SHORT on are
    all zero (one plain string.find) is summed only up to SHORT."""
    length = sum(b - a for a, b in ranges)
    segments = _segments(ranges)
    lines = [f"local {name}_P, {name}_K = crc_tables({length})",
             f"local function {name}(tail, {', '.join(f'h{i}' for i in range(1, HEAD + 1))})",
             f"  local P, acc = {name}_P, {name}_K"]
    lines += _blocks(segments, HEAD, "  ")
    rest = [(max(a, HEAD), b, pos + max(a, HEAD) - a) for a, b, pos in segments if b > HEAD]
    if max(b for _, b in ranges) > SHORT:
        lines.append(f"  if sfind(tail, CRC_ZERO_TAIL, {SHORT - HEAD + 1}, true) then  -- zeros")
        lines += [*_blocks(rest, SHORT, "    "), "    return acc", "  end"]
    lines += _blocks(rest, 1 << 30, "  ")
    lines += ["  return acc", "end"]
    return lines


def crc_functions(coverage: dict[int, list[tuple[int, int]]],
                  other: list[tuple[int, int]]) -> list[str]:
    """Lua defining ``CRC_BY_KIND[D]`` and ``CRC_OTHER`` (functions of the raw 128-byte frame
    and its first four bytes)."""
    lines = [f'local CRC_ZERO_TAIL = string.rep("\\0", C.FRAME_SIZE - {SHORT})']
    by_ranges: dict[tuple[tuple[int, int], ...], str] = {}

    def fn(ranges: list[tuple[int, int]]) -> str:
        key = tuple((int(a), int(b)) for a, b in ranges)
        name = by_ranges.get(key)
        if name is None:
            name = by_ranges[key] = f"crc_cover{len(by_ranges) + 1}"
            lines.extend(_function(name, list(key)))
        return name

    kinds = {d: fn(r) for d, r in sorted(coverage.items())}
    other_fn = fn(other)
    lines.append("local CRC_BY_KIND = {" + ", ".join(
        f"[{d}] = {name}" for d, name in kinds.items()) + "}")
    lines.append(f"local CRC_OTHER = {other_fn}")
    head_only = [d for d, r in sorted(coverage.items()) if max(b for _, b in r) <= HEAD]
    lines.append("local CRC_HEAD_ONLY = {" + ", ".join(f"[{d}] = true" for d in head_only)
                 + "}  -- kinds whose CRC covers only bytes read before the tail")
    lines.append("local CRC_RANGES = {" + ", ".join(
        f"[{name}] = {{" + ", ".join(f"{{{a}, {b}}}" for a, b in key) + "}"
        for key, name in by_ranges.items()) + "}")
    return lines


CRC_RUNTIME = r"""
-- =============================================================================================
-- CRC (decision L3), MSB-first (not reflected): the byte-wise form checks the spec's check
-- value; crc_tables(L) gives the per-position contributions of the unrolled functions below.
-- =============================================================================================
local CRC_TABLE = {}
for i = 0, 255 do
  local c = lshift(i, 8)
  for _ = 1, 8 do
    if band(c, 0x8000) ~= 0 then
      c = bxor(lshift(c, 1), C.CRC_POLY)
    else
      c = lshift(c, 1)
    end
    c = band(c, 0xFFFF)
  end
  CRC_TABLE[i] = c
end

local sbyte, ssub, sfind = string.byte, string.sub, string.find

local function crc_update(crc, s)
  for i = 1, #s do
    crc = bxor(band(lshift(crc, 8), 0xFFFF), CRC_TABLE[bxor(rshift(crc, 8), sbyte(s, i))])
  end
  return crc
end

assert(bxor(crc_update(C.CRC_INIT, "123456789"), C.CRC_XOROUT) == C.CRC_CHECK,
       "eyeq_spi: the CRC does not give the check value of specs/link.yaml")

-- one zero byte through the CRC register
local function crc_zero(r)
  return bxor(band(lshift(r, 8), 0xFFFF), CRC_TABLE[rshift(r, 8)])
end

-- P[i * 256 + b + 1]: what byte b at position i of an L-byte stream contributes; K: what the
-- initial value and the final xor contribute.
local function crc_tables(L)
  local P = {}
  for b = 0, 255 do
    local r = CRC_TABLE[b]
    for i = L - 1, 0, -1 do
      P[i * 256 + b + 1] = r
      r = crc_zero(r)
    end
  end
  local K = C.CRC_INIT
  for _ = 1, L do K = crc_zero(K) end
  return P, bxor(K, C.CRC_XOROUT)
end
"""

CRC_SELFTEST = r"""
do  -- the unrolled CRCs agree with the byte-wise one on a frame of every byte value, on one
    -- whose tail is zero (the short sum) and on one whose tail is zero but its last byte
  local t = {}
  for i = 1, C.FRAME_SIZE do t[i] = string.char((i * 37 + 11) % 256) end
  local frames = {table.concat(t)}
  for i = #CRC_ZERO_TAIL, 1, -1 do t[C.FRAME_SIZE - i + 1] = "\0" end
  frames[2] = table.concat(t)
  t[C.FRAME_SIZE] = "\1"
  frames[3] = table.concat(t)
  for _, raw in ipairs(frames) do
    for fn, ranges in pairs(CRC_RANGES) do
      local crc = C.CRC_INIT
      for i = 1, #ranges do crc = crc_update(crc, ssub(raw, ranges[i][1] + 1, ranges[i][2])) end
      assert(fn(ssub(raw, C.HEAD + 1), sbyte(raw, 1, C.HEAD)) == bxor(crc, C.CRC_XOROUT),
             "eyeq_spi: unrolled CRC disagrees")
    end
  end
end
"""
