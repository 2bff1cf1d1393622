"""The first part of the generated Lua's fixed code: items, the struct walker, the SW release.

A tree that will not be shown only needs the items a filter, column or tap references: the first
add of each field in a pass learns whether Wireshark wants it (``REF``), a group is skipped with
one look-up (``SKIP``) and a payload walked only while one of its members is referenced (``ANY``).
The release (decision D4) is chosen as ``eyeq-spi dissect`` does, from the first
``SNIFF_RECORDS`` transfers."""

from __future__ import annotations

RUNTIME_ITEMS = r"""
-- =============================================================================================
-- Items: a shown tree gets every item; a tree that is not shown only the referenced ones
-- =============================================================================================
local VIS = true            -- this packet's tree will be shown (tree.visible)
local TVB, TVB_MAKE         -- the Tvb items are added over (made on first use by TVB_MAKE)
local ROOT, ROOT_LEN, ROOT_TEXT
local REF, ANY = {}, {}     -- this pass: field -> referenced?; layout -> a member referenced?

local function range(off, len)
  local t = TVB
  if not t then
    t = TVB_MAKE()
    TVB = t
  end
  return t(off, len)
end

-- Wireshark gives the parent back for a field no filter, column or tap references.
local function learn(f, it)
  if not ROOT_TEXT then ROOT_LEN, ROOT_TEXT = ROOT.len, ROOT.text end
  REF[f] = it.len ~= ROOT_LEN or it.text ~= ROOT_TEXT
end

-- Field f over (off, len) of TVB (no range when off is nil), with value if given. Returns the
-- item in a shown tree, nil otherwise (then everything hangs on ROOT).
local function add(parent, f, off, len, value, le)
  if VIS then
    if off == nil then return parent:add(f, value) end
    if value ~= nil then return parent:add(f, range(off, len), value) end
    if le then return parent:add_le(f, range(off, len)) end
    return parent:add(f, range(off, len))
  end
  local r = REF[f]
  if r == false then return nil end
  local it
  if off == nil then
    it = ROOT:add(f, value)
  elseif value ~= nil then
    it = ROOT:add(f, range(off, len), value)
  elseif le then
    it = ROOT:add_le(f, range(off, len))
  else
    it = ROOT:add(f, range(off, len))
  end
  if r == nil then learn(f, it) end
  return nil
end

local function add_le(parent, f, off, len)
  return add(parent, f, off, len, nil, true)
end

local function expert(item, x, text)
  (item or ROOT):add_proto_expert_info(x, text)
end

-- Fields added together (every frame, every DATA frame, every message): once each has been
-- added in this pass and none is referenced, the group is skipped with one look-up. Callers on
-- the per-frame path test SKIP[g] themselves and call skip(g) only while it is nil:
--   local sk = SKIP[g]; if VIS or not (sk or sk == nil and skip(g)) then <add the group> end
local SKIP = {}  -- this pass: group -> true (skip), false (add each), nil (still learning)
local function skip(g)
  if VIS then return false end
  local sk = SKIP[g]
  if sk ~= nil then return sk end
  local all = true
  for i = 1, #g do
    local r = REF[g[i]]
    if r then
      SKIP[g] = false
      return false
    end
    if r == nil then all = false end
  end
  if all then SKIP[g] = true end
  return all
end
local G_FRAME = {F["dir"], F["frame_type"], F["header"], F["d"], F["r"], F["rsp"], F["num"],
                 F["crc"], F["crc_computed"], F["crc_ok"]}
local G_DATA = {F["transport"], F["transport_type"], F["chunk"], F["size"], F["transfer_id"],
                F["total"]}
local G_MSG = {F["msg"], F["msg_length"], F["sw"], F["sw_source"], F["app_protocol"],
               F["message"]}
local G_DASP = {F["dasp.protocol"], F["dasp.data_id"], F["dasp.counter"], F["dasp.reserved"]}

-- decimal text of the numbers the Info column shows most (NUM, RSP, IDs)
local NUMSTR = {}
for i = 0, C.SEQ_MODULO - 1 do NUMSTR[i] = tostring(i) end
-- the Info text of a consecutive frame, per transfer ID (one byte): made once each
local CONS_INFO = {}
for i = 0, 255 do CONS_INFO[i] = "consecutive ID=" .. i end

-- =============================================================================================
-- Struct walker (decision D2): S[key] rows are {offset, element size, count (0 = scalar),
-- field, child layout or false, label, flags, bits, value names}
-- =============================================================================================
local function scalar_value(o, s, m)
  local v = range(o, s):le_uint()
  return band(rshift(v, m[8][1]), m[8][2])
end

local function add_scalar(parent, m, o, s)
  if m[8] then
    local v = scalar_value(o, s, m)
    local it = add(parent, m[4], o, s, v)
    if it and m[9] then it:append_text(" (" .. (m[9][v] or "?") .. ")") end
    return it
  end
  local it = add_le(parent, m[4], o, s)
  if it and m[9] then
    local v = range(o, s):le_uint()
    it:append_text(" (" .. (m[9][v] or "?") .. ")")
  end
  local flags = m[7]
  if flags then
    for i = 1, #flags do add_le(it, flags[i], o, s) end
  end
  return it
end

local function walk(tree, base, key)
  local rows = S[key]
  for i = 1, #rows do
    local m = rows[i]
    local o, s, n, f, c = base + m[1], m[2], m[3], m[4], m[5]
    if c then
      if n == 0 then
        walk(tree:add(f, range(o, s)), o, c)
      else
        for k = 0, n - 1 do
          local at = o + k * s
          local it = tree:add(f, range(at, s))
          it:append_text("[" .. k .. "]")
          walk(it, at, c)
        end
      end
    elseif n == 0 then
      if m[7] or m[8] or m[9] then
        add_scalar(tree, m, o, s)
      else
        tree:add_le(f, TVB(o, s))  -- the common member, without the helpers (TVB exists here)
      end
    else
      local arr = tree:add(range(o, s * n), m[6] .. "[" .. n .. "]")
      for k = 0, n - 1 do
        add_scalar(arr, m, o + k * s, s):prepend_text("[" .. k .. "] ")
      end
    end
  end
end

-- The same walk for a tree that is not shown: only referenced members, and a layout none of
-- whose members is referenced is not walked again in this pass.
local function walk_hidden(base, key)
  local any = ANY[key]
  if any == false then return false end
  any = false
  local rows = S[key]
  for i = 1, #rows do
    local m = rows[i]
    local o, s, n, f, c = base + m[1], m[2], m[3], m[4], m[5]
    if c then
      if REF[f] ~= false then
        for k = 0, math.max(n, 1) - 1 do add(nil, f, o + k * s, s) end
      end
      for k = 0, math.max(n, 1) - 1 do
        if walk_hidden(o + k * s, c) then any = true end
      end
      any = any or REF[f]
    else
      local flags = m[7]
      if REF[f] ~= false or flags then
        for k = 0, math.max(n, 1) - 1 do add_scalar(nil, m, o + k * s, s) end
      end
      if REF[f] then any = true end
      if flags then
        for j = 1, #flags do
          if REF[flags[j]] then any = true end
        end
      end
    end
  end
  ANY[key] = any
  return any
end

-- =============================================================================================
-- SW release (decision D4): the preference, else the capture's "eyeq-spi sw=<release>"
-- comment, else what the EyeQ reports (GetEyeQVersions reply, boot status, base diagnostics),
-- else the release whose DASP layouts fit the payload lengths, else the newest. Evidence is
-- taken from the first SNIFF_RECORDS transfers, as `eyeq-spi dissect` does.
-- =============================================================================================
p.prefs.sw = Pref.enum("SW release", PREF_DEFAULT,
                       "DASP layouts of this release, whatever the capture says (auto: the " ..
                       "capture's own release)", PREF_CHOICES, false)
local PREF = PREF_DEFAULT
local REL_MM = {}
for i = 1, #RELEASES do
  local a, b = RELEASES[i]:match("^(%d+)%.(%d+)$")
  REL_MM[i] = tonumber(a) * 1000 + tonumber(b)
end

-- the listed release for a reported one: the same, else the newest before it (D4)
local function listed(major, minor)
  local v, best = major * 1000 + minor, nil
  for i = 1, #RELEASES do
    if REL_MM[i] <= v then best = i end
  end
  return best
end

local function release_of_text(text)
  local a, b = text:lower():gsub("^sw", ""):match("^(%d+)[._]?(%d*)$")
  if not a then return nil end
  local ri = nil
  for i = 1, #RELEASES do
    if REL_MM[i] == tonumber(a) * 1000 + (tonumber(b) or 0) then ri = i end
  end
  return ri
end

local REL  -- ri, src: the capture's release so far; final: from a comment or a report
local rel_notes  -- frame -> the one line saying the preference overrides the capture

local function found(ri, src, n)
  REL.ri, REL.src, REL.final = ri, src, true
  if PREF > 0 and PREF ~= ri then
    rel_notes[n] = string.format("read as SW %s (preference) although the capture says SW %s (%s)",
                                 RELEASES[PREF], RELEASES[ri], src)
    expert(nil, X.note, rel_notes[n])
  end
end

local function fit(id, len)
  local key = id * 65536 + len
  if REL.pairs[key] then return end
  REL.pairs[key] = {id, len}
  local best, score = 0, {}
  for ri = 1, #RELEASES do
    local s = 0
    for _, pr in pairs(REL.pairs) do
      if SIZES[ri][pr[1]] == pr[2] - 4 then s = s + 1 end
    end
    score[ri] = s
    if s > best then best = s end
  end
  if best == 0 then return end
  local names = {}
  for ri = 1, #RELEASES do
    if score[ri] == best then
      names[#names + 1] = RELEASES[ri]
      REL.ri = ri
    end
  end
  REL.src = "DASP payload lengths (fit " .. table.concat(names, ", ") .. ")"
end

-- what a message of the first SNIFF_RECORDS transfers says about the release
local function evidence(data, n)
  local len = #data
  local b0, b1, b2 = sbyte(data, 1, 3)
  if len >= 5 and b1 == MESP_PROTOCOL and b0 == b2 then
    local func, tag = sbyte(data, 4, 5)
    local at = 10 + math.max(VERSIONS.major, VERSIONS.minor)
    if b0 * 256 + func == VERSIONS.key and band(tag, MESP_REPLY_MASK) ~= 0 and len >= at
        and sbyte(data, 6) + sbyte(data, 7) + sbyte(data, 8) + sbyte(data, 9) == 0 then
      local ri = listed(sbyte(data, 10 + VERSIONS.major), sbyte(data, 10 + VERSIONS.minor))
      if ri then found(ri, "GetEyeQVersions reply", n) end
    end
  elseif b0 == BOOT.id and BOOT.at[len] then
    local ri = listed(sbyte(data, BOOT.at[len] + 1), sbyte(data, BOOT.at[len] + 2))
    if ri then found(ri, "boot status", n) end
  elseif b0 == DASP_PROTOCOL and len >= 4 then
    if b1 == BASE_DIAG.id and len > BASE_DIAG.minor then
      local ri = listed(sbyte(data, BASE_DIAG.major + 1), sbyte(data, BASE_DIAG.minor + 1))
      if ri then
        found(ri, "EYEQ_BASE_DIAG_STATUS_MSG", n)
        return
      end
    end
    fit(b1, len)
  end
end

local function release()
  if PREF > 0 then return PREF, "preference" end
  return REL.ri, REL.src
end

"""
