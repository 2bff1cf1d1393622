"""The fixed part of the generated Lua: CRC, struct walker, application and link dissectors.

It holds no protocol numbers: every constant it uses (``C``, ``HDR``, ``KIND``, ``COVER``,
``TTYPE``, ``DIRS``, ``RX_LIMIT``, ``S``, ``DASP``, ``OTHER``, ``MESP`` ...) is emitted from
``specs/`` by :mod:`eyeq_spi.wireshark.lua_gen` before this text. Lua 5.2 only: bit operations
go through Wireshark's ``bit`` library (``band``, ``bxor``, ``lshift``, ``rshift`` are locals).
"""

from __future__ import annotations

RUNTIME = r"""
-- =============================================================================================
-- CRC (decision L3), table-driven, MSB-first (not reflected)
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

local sbyte, ssub = string.byte, string.sub

local function crc_update(crc, s)
  for i = 1, #s do
    crc = bxor(band(lshift(crc, 8), 0xFFFF), CRC_TABLE[bxor(rshift(crc, 8), sbyte(s, i))])
  end
  return crc
end

-- ranges: {{start, end}, ...}, end exclusive, 0-based, over the raw transfer
local function crc_over(raw, ranges)
  local crc = C.CRC_INIT
  for i = 1, #ranges do
    crc = crc_update(crc, ssub(raw, ranges[i][1] + 1, ranges[i][2]))
  end
  return bxor(crc, C.CRC_XOROUT)
end

assert(bxor(crc_update(C.CRC_INIT, "123456789"), C.CRC_XOROUT) == C.CRC_CHECK,
       "eyeq_spi: the CRC does not give the check value of specs/link.yaml")

-- =============================================================================================
-- Struct walker (decision D2): S[name] rows are
-- {offset, element size, count (0 = scalar), field, child struct or false, label, flags}
-- =============================================================================================
local function add_flags(tree, range, flags)
  for i = 1, #flags do
    tree:add_le(flags[i], range)
  end
end

local function walk(tvb, tree, base, rows)
  for i = 1, #rows do
    local m = rows[i]
    local o, s, n, f, c = base + m[1], m[2], m[3], m[4], m[5]
    if c then
      local child = S[c]
      if n == 0 then
        walk(tvb, tree:add(f, tvb(o, s)), o, child)
      else
        for k = 0, n - 1 do
          local at = o + k * s
          local it = tree:add(f, tvb(at, s))
          it:append_text("[" .. k .. "]")
          walk(tvb, it, at, child)
        end
      end
    elseif n == 0 then
      local it = tree:add_le(f, tvb(o, s))
      if m[7] then add_flags(it, tvb(o, s), m[7]) end
    else
      local arr = tree:add(tvb(o, s * n), m[6] .. "[" .. n .. "]")
      for k = 0, n - 1 do
        local r = tvb(o + k * s, s)
        local it = arr:add_le(f, r)
        it:prepend_text("[" .. k .. "] ")
        if m[7] then add_flags(it, r, m[7]) end
      end
    end
  end
end

-- =============================================================================================
-- Application messages (decisions A, M, D)
-- =============================================================================================
local function dissect_payload(tvb, mt, off, entry)
  local n = tvb:len() - off
  if n ~= entry.size then
    mt:add_proto_expert_info(X.length_mismatch, string.format(
      "length mismatch: %s payload is %d bytes, the %s layout is %d",
      entry.name, n, SW, entry.size))
    return false
  end
  walk(tvb, mt:add(entry.field, tvb(off, n)), off, S[entry.struct])
  return true
end

local function mesp_params(tvb, tree, off, rows)
  local n = tvb:len()
  for i = 1, #rows do
    local r = rows[i]
    local w = MESP_WIDTH[r[1]]
    if w then
      if off + w > n then return off, r[3] end
      tree:add_le(r[2], tvb(off, w))
      off = off + w
    else
      if off + 4 > n then return off, r[3] end
      local len = tvb(off, 4):le_uint()
      if off + 4 + len > n then return off, r[3] end
      tree:add_le(F["mesp.length"], tvb(off, 4)):prepend_text(r[3] .. " ")
      if len > 0 then
        tree:add(r[2], tvb(off + 4, len))
      elseif r[1] == "string" then
        tree:add(r[2], tvb(off, 4), "")
      else
        tree:add(tvb(off, 4), r[3] .. ": (empty)")
      end
      off = off + 4 + len
    end
  end
  return off, nil
end

local function dissect_mesp(tvb, mt)
  local n = tvb:len()
  mt:add(F["app_protocol"], tvb(1, 1), "MESP")
  if n < 5 then
    mt:add_proto_expert_info(X.malformed, "MESP message of " .. n .. " bytes has no full header")
    return "MESP (short)"
  end
  mt:add(F["mesp.service"], tvb(0, 1))
  mt:add(F["mesp.protocol"], tvb(1, 1))
  mt:add(F["mesp.service_repeat"], tvb(2, 1))
  mt:add(F["mesp.function"], tvb(3, 1))
  local tt = mt:add(F["mesp.tag"], tvb(4, 1))
  tt:add(F["mesp.counter"], tvb(4, 1))
  tt:add(F["mesp.reply"], tvb(4, 1))
  local tag = tvb(4, 1):uint()
  local reply = band(tag, MESP_REPLY_MASK) ~= 0
  if band(tag, MESP_TAG_SPARE) ~= 0 then
    tt:add_proto_expert_info(X.note, "tag bits outside counter and reply are set (M1 says 0)")
  end
  local service, func = tvb(0, 1):uint(), tvb(3, 1):uint()
  local fn = MESP[service * 256 + func]
  if not fn then
    mt:add_proto_expert_info(X.unknown, string.format(
      "unknown MESP service/function 0x%02X/0x%02X", service, func))
    return string.format("MESP 0x%02X/0x%02X", service, func)
  end
  mt:add(F["mesp.name"], tvb(3, 1), fn.name)
  local what = fn.name .. (reply and " reply" or " request")
  mt:add(F["message"], tvb(3, 1), fn.name)
  local off, bad
  if reply then
    if n < 9 then
      mt:add_proto_expert_info(X.malformed, "MESP reply without its 4-byte ret")
      return what
    end
    mt:add_le(F["mesp.ret"], tvb(5, 4))
    local ret = tvb(5, 4):le_uint()
    if ret ~= 0 then what = what .. " ret=" .. ret end
    if ret ~= 0 and n == 9 then return what end
    off, bad = mesp_params(tvb, mt, 9, fn.rep)
  else
    off, bad = mesp_params(tvb, mt, 5, fn.req)
  end
  if bad then
    mt:add_proto_expert_info(X.malformed, fn.name .. ": parameter " .. bad .. " is cut short")
  elseif off ~= n then
    mt:add_proto_expert_info(X.malformed, string.format(
      "%s: %d bytes after the last parameter", fn.name, n - off))
  end
  return what
end

local function dissect_dasp(tvb, mt)
  local n = tvb:len()
  mt:add(F["app_protocol"], tvb(0, 1), "DASP")
  if n < 4 then
    mt:add_proto_expert_info(X.malformed, "BadHdr: DASP message of " .. n .. " bytes")
    return "DASP (short)"
  end
  mt:add(F["dasp.protocol"], tvb(0, 1))
  mt:add(F["dasp.data_id"], tvb(1, 1))
  mt:add(F["dasp.counter"], tvb(2, 1))
  local rt = mt:add(F["dasp.reserved"], tvb(3, 1))
  if tvb(3, 1):uint() ~= 0 then
    rt:add_proto_expert_info(X.note, "DASP reserved byte is not 0")
  end
  local id = tvb(1, 1):uint()
  local entry = DASP[id]
  if not entry then
    mt:add_proto_expert_info(X.unknown, string.format(
      "BadHdr: unknown DASP data ID 0x%02X in %s", id, SW))
    return string.format("DASP 0x%02X", id)
  end
  mt:add(F["message"], tvb(1, 1), entry.name)
  dissect_payload(tvb, mt, 4, entry)
  return entry.name .. " #" .. tvb(2, 1):uint()
end

local function dissect_other(tvb, mt, entry)
  mt:add(F["app_protocol"], tvb(0, 1), entry.protocol)
  mt:add(F["msg_id"], tvb(0, 1))
  mt:add(F["message"], tvb(0, 1), entry.name)
  dissect_payload(tvb, mt, 1, entry)
  return entry.name
end

-- Decision A: route a whole message by its first bytes.
local function dissect_message(tvb, root)
  local n = tvb:len()
  local mt = root:add(F["msg"], tvb())
  mt:add(F["msg_length"], tvb(), n)
  local b0 = tvb(0, 1):uint()
  local name
  if n >= 3 and tvb(1, 1):uint() == MESP_PROTOCOL and b0 == tvb(2, 1):uint() then
    name = dissect_mesp(tvb, mt)
  elseif b0 == DASP_PROTOCOL then
    name = dissect_dasp(tvb, mt)
  elseif OTHER[b0] then
    name = dissect_other(tvb, mt, OTHER[b0])
  else
    mt:add(F["app_protocol"], tvb(0, 1), "UNKNOWN")
    mt:add_proto_expert_info(X.unknown, string.format("unknown message: first byte 0x%02X", b0))
    name = string.format("unknown message 0x%02X", b0)
  end
  mt:append_text(": " .. name)
  return name
end

-- =============================================================================================
-- Transport (decisions T1-T6) and reassembly across frames
-- =============================================================================================
-- Each frame is fed to the reassembly once, in capture order, the first time it is dissected
-- with its direction known: on the first pass normally (not pinfo.visited). A pass that builds
-- no protocol tree (tshark -2's first pass) cannot read frame.interface_id; its frames are fed
-- on the next pass, which runs in capture order too. rx[direction] holds the open transfer of
-- that direction; done[frame number] keeps the reassembled bytes of the frame that completed a
-- message, notes[] the reassembly events of a frame, reasm_in[] the completing frame of every
-- fragment. Later passes only read these tables.
local f_iface = Field.new("frame.interface_id")
local f_number = Field.new("frame.number")
local rx, done, notes, reasm_in, last_fed

local function reset_state()
  rx, done, notes, reasm_in, last_fed = {}, {}, {}, {}, 0
end
reset_state()

function p.init()
  reset_state()
end

-- "h2e"/"e2h" from the pcapng interface; "?" when the capture has no interfaces; nil when this
-- pass builds no tree, so no field can be read.
local function direction()
  local fi = f_iface()
  if fi then return DIRS[fi.value] or ("interface " .. fi.value) end
  if f_number() then return "?" end
  return nil
end

-- A filtering tap makes Wireshark build a tree on its first pass, so frames get their direction
-- (and are fed to the reassembly) in capture order.
local direction_tap = Listener.new(nil, "eyeq_spi")

local function note(pinfo, text)
  local t = notes[pinfo.number]
  if not t then
    t = {}
    notes[pinfo.number] = t
  end
  t[#t + 1] = text
end

local function abort(st, pinfo, reason)
  local o = st.open
  if not o then return end
  st.open = nil
  st.dead = o.id
  note(pinfo, string.format("transfer %d abandoned (%s) after %d of %d bytes, started in frame %d",
                            o.id, reason, o.len, o.total, o.frames[1]))
end

-- Returns the Info text and, for a trusted single frame, the message as a Tvb.
local function dissect_transport(tvb, pinfo, root, dir, num, trusted, feed)
  local ttype = tvb(C.T_TYPE, 1):uint()
  local tname = TTYPE[ttype]
  local tt = root:add(F["transport"], tvb(C.T_TYPE, 1), tname or "invalid")
  tt:add(F["transport_type"], tvb(C.T_TYPE, 1))
  local st
  if trusted and feed then
    st = rx[dir]
    if not st then
      st = {}
      rx[dir] = st
    end
    if st.last == num then
      note(pinfo, "duplicate of the previous DATA frame (NUM " .. num .. "): not reassembled")
      st = nil
    else
      st.last = num
      local o = st.open
      if o and pinfo.abs_ts - o.time >= C.REASSEMBLY_TIMEOUT then abort(st, pinfo, "timeout") end
    end
  end
  if ttype == C.T_SINGLE then
    local size = tvb(C.T_ARG, 1):uint()
    tt:add(F["size"], tvb(C.T_ARG, 1))
    if size < 1 or size > C.SINGLE_MAX then
      tt:add_proto_expert_info(X.format, string.format(
        "single frame size %d outside 1..%d (T2)", size, C.SINGLE_MAX))
      return "single size=" .. size, nil
    end
    tt:add(F["chunk"], tvb(C.SINGLE_DATA, size))
    if st and st.open then abort(st, pinfo, "interleaved") end
    if not trusted then return "single", nil end
    return "single", tvb(C.SINGLE_DATA, size):tvb()
  elseif ttype == C.T_FIRST then
    local tid = tvb(C.T_ARG, 1):uint()
    local total = tvb(C.T_TOTAL, 4):le_uint()
    tt:add(F["transfer_id"], tvb(C.T_ARG, 1))
    tt:add_le(F["total"], tvb(C.T_TOTAL, 4))
    tt:add(F["chunk"], tvb(C.FIRST_DATA, C.FIRST_CHUNK))
    local limit = RX_LIMIT[dir] or C.MAX_TOTAL
    if total < C.FIRST_TOTAL_MIN or total > limit then
      tt:add_proto_expert_info(X.format, string.format(
        "first frame total %d outside %d..%d (T3, T6)", total, C.FIRST_TOTAL_MIN, limit))
      return "first ID=" .. tid .. " total=" .. total, nil
    end
    if st then
      abort(st, pinfo, "new_first_frame")
      st.dead = nil
      st.open = {id = tid, total = total, parts = {tvb:raw(C.FIRST_DATA, C.FIRST_CHUNK)},
                 len = C.FIRST_CHUNK, last = num, time = pinfo.abs_ts, frames = {pinfo.number}}
    end
    return "first ID=" .. tid .. " total=" .. total, nil
  elseif ttype == C.T_CONSECUTIVE then
    local tid = tvb(C.T_ARG, 1):uint()
    tt:add(F["transfer_id"], tvb(C.T_ARG, 1))
    tt:add(F["chunk"], tvb(C.NEXT_DATA, C.CONSECUTIVE_CHUNK))
    if st then
      local o = st.open
      if not o then
        if tid ~= st.dead then note(pinfo, "consecutive frame with no open transfer") end
      elseif tid ~= o.id then
        abort(st, pinfo, "wrong_id")
      elseif num ~= (o.last + 1) % C.SEQ_MODULO then
        abort(st, pinfo, "num_gap")
      elseif o.total - o.len < C.CONSECUTIVE_CHUNK
          and tvb:raw(C.NEXT_DATA + o.total - o.len, C.CONSECUTIVE_CHUNK - (o.total - o.len))
              :find("[^\0]") then
        abort(st, pinfo, "bad_padding")  -- T4/T6a: the rest is zero; this is another transfer
      else
        local take = math.min(C.CONSECUTIVE_CHUNK, o.total - o.len)
        o.parts[#o.parts + 1] = tvb:raw(C.NEXT_DATA, take)
        o.len = o.len + take
        o.last = num
        o.time = pinfo.abs_ts
        o.frames[#o.frames + 1] = pinfo.number
        if o.len >= o.total then
          st.open = nil
          done[pinfo.number] = {data = table.concat(o.parts), frames = o.frames}
          for _, fnum in ipairs(o.frames) do reasm_in[fnum] = pinfo.number end
        end
      end
    end
    return "consecutive ID=" .. tid, nil
  end
  tt:add_proto_expert_info(X.format, string.format("transport type 0x%02X is not 0..2 (T1)", ttype))
  return string.format("transport 0x%02X", ttype), nil
end

-- =============================================================================================
-- Link layer (decisions L1-L8) and the dissector
-- =============================================================================================
function p.dissector(tvb, pinfo, tree)
  pinfo.cols.protocol = "EyeQ SPI"
  local n = tvb:len()
  local root = tree:add(p, tvb())
  local dir = direction()
  local info = ""
  local feed = false
  if dir then
    if dir ~= "?" then root:add(F["dir"], dir) end
    info = dir .. " "
    feed = pinfo.number > last_fed
    if feed then last_fed = pinfo.number end
  end
  if n ~= C.FRAME_SIZE then
    root:add(F["bad_length"], true)
    root:add(F["length"], n)
    root:add_proto_expert_info(X.bad_length, string.format(
      "malformed transfer: %d bytes, not %d (L8)", n, C.FRAME_SIZE))
    pinfo.cols.info = info .. "bad length " .. n
    return n
  end
  local raw = tvb:raw(0, n)
  local h = tvb(0, 4):le_uint()
  local d = band(rshift(h, HDR.D[1]), HDR.D[2])
  local r = band(rshift(h, HDR.R[1]), HDR.R[2])
  local rsp = band(rshift(h, HDR.RSP[1]), HDR.RSP[2])
  local num = band(rshift(h, HDR.NUM[1]), HDR.NUM[2])
  local kind = KIND[d] or "INVALID"
  root:add(F["frame_type"], tvb(0, 4), kind)
  local ht = root:add_le(F["header"], tvb(0, 4))
  ht:add_le(F["d"], tvb(0, 4))
  ht:add_le(F["r"], tvb(0, 4))
  ht:add_le(F["rsp"], tvb(0, 4))
  ht:add_le(F["num"], tvb(0, 4))
  if kind == "INVALID" then
    ht:add_proto_expert_info(X.format, string.format("D=0x%X is not a frame kind (L2)", d))
  end
  if r ~= 0 then
    ht:add_proto_expert_info(X.format, string.format("R=0x%X, reserved must be 0 (L2)", r))
  end
  local crc = crc_over(raw, COVER[d] or COVER_OTHER)
  local got = tvb(C.CRC_OFFSET, 2):le_uint()
  local ct = root:add_le(F["crc"], tvb(C.CRC_OFFSET, 2))
  ct:add(F["crc_computed"], tvb(C.CRC_OFFSET, 2), crc)
  ct:add(F["crc_ok"], tvb(C.CRC_OFFSET, 2), crc == got)
  if crc ~= got then
    ct:add_proto_expert_info(X.bad_crc, string.format("CRC 0x%04X, computed 0x%04X (L3)", got, crc))
  end
  info = info .. kind
  if kind == "DATA" then
    info = info .. " NUM=" .. num .. " RSP=" .. rsp
  elseif kind == "ACK" then
    info = info .. " of NUM=" .. rsp
  elseif kind == "NAK" then
    info = info .. " of NUM=" .. rsp .. " " .. (NAK_REASONS[num] or string.format("0x%03X", num))
    local nt = root:add(F["nak_reason"], tvb(0, 4), num)
    nt:add_proto_expert_info(X.nak, string.format("NAK of NUM %d: %s", rsp,
                                                  NAK_REASONS[num] or "unknown reason"))
  else
    info = info .. string.format(" D=0x%X", d)
  end
  if crc ~= got then info = info .. " [bad CRC]" end
  if kind == "DATA" then
    local trusted = crc == got and r == 0
    local tinfo, mtvb = dissect_transport(tvb, pinfo, root, dir, num, trusted, feed)
    info = info .. " " .. tinfo
    local nt = notes[pinfo.number]
    if nt then
      for i = 1, #nt do root:add_proto_expert_info(X.reassembly, nt[i]) end
    end
    local dn = done[pinfo.number]
    if dn then
      local rt = root:add(F["fragment_count"], #dn.frames)
      for i = 1, #dn.frames do rt:add(F["fragment"], dn.frames[i]) end
      mtvb = ByteArray.new(dn.data, true):tvb("Reassembled EyeQ message")
    elseif reasm_in[pinfo.number] then
      root:add(F["reassembled_in"], reasm_in[pinfo.number])
    end
    if mtvb then info = info .. ": " .. dissect_message(mtvb, root) end
  end
  pinfo.cols.info = info
  return n
end
"""
