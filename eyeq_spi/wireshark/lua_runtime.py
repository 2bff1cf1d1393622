"""The second part of the generated Lua's fixed code: messages, transport and link layer.

It holds no protocol numbers: every constant (``C``, ``KIND``, ``S``, ``MSG``, ``MESP`` ...) is
emitted from ``specs/`` by :mod:`eyeq_spi.wireshark.lua_gen` before this text, which writes each
``C.NAME`` as its value and each ``@HDR.<field>@`` as arithmetic on the header word ``h`` (Lua
5.2's ``bit`` library costs a C call per operation). State is kept by frame number in flat
tables, set on the first pass and only read on later passes."""

from __future__ import annotations

RUNTIME = r"""
-- =============================================================================================
-- Application messages (decisions A, M, D)
-- =============================================================================================
local function dissect_payload(mt, off, len, entry, ri)
  local n = len - off
  if n ~= entry.size then
    expert(mt, X.length_mismatch, string.format(
      "length mismatch: %s payload is %d bytes, the SW %s layout is %d",
      entry.name, n, RELEASES[ri], entry.size))
    return
  end
  if VIS then
    walk(mt:add(entry.field, range(off, n)), off, entry.struct)
  elseif ANY[entry.struct] ~= false or REF[entry.field] ~= false then
    add(nil, entry.field, off, n)
    walk_hidden(off, entry.struct)
  end
end

local function mesp_params(data, tree, off, rows)
  local n = #data
  for i = 1, #rows do
    local r = rows[i]
    local w = MESP_WIDTH[r[1]]
    if w then
      if off + w > n then return off, r[3] end
      add_le(tree, r[2], off, w)
      off = off + w
    else
      if off + 4 > n then return off, r[3] end
      local a, b, c, d = sbyte(data, off + 1, off + 4)
      local len = a + b * 256 + c * 65536 + d * 16777216
      if off + 4 + len > n then return off, r[3] end
      local lt = add_le(tree, F["mesp.length"], off, 4)
      if lt then lt:prepend_text(r[3] .. " ") end
      if len > 0 then
        add(tree, r[2], off + 4, len)
      elseif r[1] == "string" then
        add(tree, r[2], off, 4, "")
      elseif VIS then
        tree:add(range(off, 4), r[3] .. ": (empty)")
      end
      off = off + 4 + len
    end
  end
  return off, nil
end

local function dissect_mesp(data, mt)
  local n = #data
  add(mt, F["app_protocol"], 1, 1, "MESP")
  if n < 5 then
    expert(mt, X.malformed, "MESP message of " .. n .. " bytes has no full header")
    return "MESP (short)"
  end
  local service, _, _, func, tag = sbyte(data, 1, 5)
  add(mt, F["mesp.service"], 0, 1)
  add(mt, F["mesp.protocol"], 1, 1)
  add(mt, F["mesp.service_repeat"], 2, 1)
  add(mt, F["mesp.function"], 3, 1)
  local tt = add(mt, F["mesp.tag"], 4, 1)
  add(tt, F["mesp.counter"], 4, 1)
  add(tt, F["mesp.reply"], 4, 1)
  local reply = band(tag, MESP_REPLY_MASK) ~= 0
  if band(tag, MESP_TAG_SPARE) ~= 0 then
    expert(tt, X.note, "tag bits outside counter and reply are set (M1 says 0)")
  end
  local fn = MESP[service * 256 + func]
  if not fn then
    expert(mt, X.unknown, string.format("unknown MESP service/function 0x%02X/0x%02X",
                                        service, func))
    return string.format("MESP 0x%02X/0x%02X", service, func)
  end
  add(mt, F["mesp.name"], 3, 1, fn.name)
  local what = fn.name .. (reply and " reply" or " request")
  add(mt, F["message"], 3, 1, fn.name)
  local off, bad
  if reply then
    if n < 9 then
      expert(mt, X.malformed, "MESP reply without its 4-byte ret")
      return what
    end
    add_le(mt, F["mesp.ret"], 5, 4)
    local a, b, c, d = sbyte(data, 6, 9)
    local ret = a + b * 256 + c * 65536 + d * 16777216
    if ret ~= 0 then what = what .. " ret=" .. ret end
    if ret ~= 0 and n == 9 then return what end
    off, bad = mesp_params(data, mt, 9, fn.rep)
  else
    off, bad = mesp_params(data, mt, 5, fn.req)
  end
  if bad then
    expert(mt, X.malformed, fn.name .. ": parameter " .. bad .. " is cut short")
  elseif off ~= n then
    expert(mt, X.malformed, string.format("%s: %d bytes after the last parameter",
                                          fn.name, n - off))
  end
  return what
end

local function dissect_dasp(data, mt, ri, items)
  local n = #data
  if items then add(mt, F["app_protocol"], 0, 1, "DASP") end
  if n < 4 then
    expert(mt, X.malformed, "BadHdr: DASP message of " .. n .. " bytes")
    return "DASP (short)"
  end
  local rt
  local sk = SKIP[G_DASP]
  if VIS or not (sk or sk == nil and skip(G_DASP)) then
    add(mt, F["dasp.protocol"], 0, 1)
    add(mt, F["dasp.data_id"], 1, 1)
    add(mt, F["dasp.counter"], 2, 1)
    rt = add(mt, F["dasp.reserved"], 3, 1)
  end
  local _, id, counter, reserved = sbyte(data, 1, 4)
  if reserved ~= 0 then expert(rt, X.note, "DASP reserved byte is not 0") end
  local entry = DASP_R[ri][id]
  if not entry then
    expert(mt, X.unknown, string.format("BadHdr: unknown DASP data ID 0x%02X in SW %s",
                                        id, RELEASES[ri]))
    return string.format("DASP 0x%02X", id)
  end
  if items then add(mt, F["message"], 1, 1, entry.name) end
  dissect_payload(mt, 4, n, entry, ri)
  -- the name and counter, made once per message and counter value (a byte)
  local named = entry.counted
  if not named then
    named = {}
    entry.counted = named
  end
  local text = named[counter]
  if not text then
    text = entry.name .. " #" .. NUMSTR[counter]
    named[counter] = text
  end
  return text
end

local function dissect_other(data, mt, entry, ri, items)
  if items then
    add(mt, F["app_protocol"], 0, 1, entry.protocol)
    add(mt, F["message"], 0, 1, entry.name)
  end
  add(mt, F["msg_id"], 0, 1)
  dissect_payload(mt, 1, #data, entry, ri)
  return entry.name
end

-- Decision A: route a whole message (a string; its Tvb is made only if an item needs it).
local function dissect_message(data, make_tvb)
  TVB, TVB_MAKE = nil, make_tvb
  local n = #data
  local ri, src = release()
  local sk = SKIP[G_MSG]
  local items = VIS or not (sk or sk == nil and skip(G_MSG))
  local mt
  if items then
    mt = add(ROOT, F["msg"], 0, n)
    add(mt, F["msg_length"], 0, n, n)
    add(mt, F["sw"], nil, nil, RELEASES[ri])
    add(mt, F["sw_source"], nil, nil, src)
  end
  local b0, b1, b2 = sbyte(data, 1, 3)
  local name
  if n >= 3 and b1 == MESP_PROTOCOL and b0 == b2 then
    name = dissect_mesp(data, mt)
  elseif b0 == DASP_PROTOCOL then
    name = dissect_dasp(data, mt, ri, items)
  elseif OTHER_R[ri][b0] then
    name = dissect_other(data, mt, OTHER_R[ri][b0], ri, items)
  else
    if items then add(mt, F["app_protocol"], 0, 1, "UNKNOWN") end
    expert(mt, X.unknown, string.format("unknown message: first byte 0x%02X", b0))
    name = string.format("unknown message 0x%02X", b0)
  end
  if mt then mt:append_text(": " .. name) end
  return name
end

-- =============================================================================================
-- Transport (decisions T1-T6) and reassembly across frames
-- =============================================================================================
-- Each frame is fed to the reassembly once, in capture order, the first time it is dissected
-- with its direction known: on the first pass normally. A pass that builds no protocol tree
-- (tshark -2's first pass) cannot read frame.interface_id; its frames are fed on the next pass,
-- which runs in capture order too. rx[direction] holds that direction's transfer; done[frame]
-- the message a frame completed, prev[frame] the previous fragment of a fragment, reasm_in[]
-- the completing frame of every fragment, notes[] a frame's reassembly events, crc_bad[] the
-- computed CRC of a frame whose CRC was bad. Later passes only read these tables.
local f_iface = Field.new("frame.interface_id")
-- the frame protocol item, present in every pass that builds a tree: Wireshark makes it for
-- every Lua field extractor anyway, where frame.number would be one more item per packet
local f_frame = Field.new("frame")
local f_comment
do
  local ok, fld = pcall(Field.new, "frame.comment")
  if ok then f_comment = fld end
end
local rx, done, prev, reasm_in, notes, crc_bad, last_fed, prev_number
local COLS  -- this pass: the columns are filled (nil: not known yet)

local function new_pass()
  REF, ANY, SKIP, COLS = {}, {}, {}, nil
end

local function reset_state()
  rx, done, prev, reasm_in, notes, crc_bad = {}, {}, {}, {}, {}, {}
  last_fed, prev_number = 0, math.huge
  new_pass()
  REL = {ri = NEWEST, src = "default", final = false, pairs = {}}
  rel_notes = {}
  PREF = p.prefs.sw
end
reset_state()

function p.init()
  reset_state()
end

function p.prefs_changed()
  PREF = p.prefs.sw
end

-- A filtering tap makes Wireshark build a tree on its first pass too (tshark -2), so frames get
-- their direction, are fed to the reassembly and show their release in capture order.
local direction_tap = Listener.new(nil, "eyeq_spi")

-- "h2e"/"e2h" from the pcapng interface; "?" when the capture has no interfaces; nil when this
-- pass builds no tree, so no field can be read.

local function comment(n)
  for _, fi in ipairs({f_comment()}) do
    local text = tostring(fi.value):match("eyeq%-spi sw=(%S+)")
    local ri = text and release_of_text(text)
    if ri then
      found(ri, "capture", n)
      return
    end
  end
end

local function note(n, text)
  local t = notes[n]
  if not t then
    t = {}
    notes[n] = t
  end
  t[#t + 1] = text
end

local function abort(st, n, reason)
  if not st.open then return end
  st.open = false
  st.dead = st.id
  note(n, string.format("transfer %d abandoned (%s) after %d of %d bytes, started in frame %d",
                        st.id, reason, st.len, st.total, st.first))
end

local function u32(raw, at)
  local a, b, c, d = sbyte(raw, at + 1, at + 4)
  return a + b * 256 + c * 65536 + d * 16777216
end

-- Returns the Info text (when the columns are filled) and, for a trusted single frame, the
-- message bytes. ttype and targ are the frame's bytes T_TYPE and T_ARG.
local function dissect_transport(tail, pinfo, dir, num, trusted, feed, n, cols, ttype, targ)
  local sk = SKIP[G_DATA]
  local items = VIS or not (sk or sk == nil and skip(G_DATA))
  local tt
  if items then
    tt = add(ROOT, F["transport"], C.T_TYPE, 1, TTYPE[ttype] or "invalid")
    add(tt, F["transport_type"], C.T_TYPE, 1)
  end
  local st, now
  if trusted and feed then
    st = rx[dir]
    if not st then
      st = {open = false, parts = {}}
      rx[dir] = st
    end
    if st.lastnum == num then
      note(n, "duplicate of the previous DATA frame (NUM " .. num .. "): not reassembled")
      st = nil
    else
      st.lastnum = num
      -- the time, read once (each read is a call into Wireshark), only where it matters: an
      -- open transfer may time out, a first or consecutive frame records it
      if st.open or ttype ~= C.T_SINGLE then
        now = pinfo.abs_ts
        if st.open and now - st.time >= C.REASSEMBLY_TIMEOUT then
          abort(st, n, "timeout")
        end
      end
    end
  end
  if ttype == C.T_SINGLE then
    if items then add(tt, F["size"], C.T_ARG, 1) end
    if targ < 1 or targ > C.SINGLE_MAX then
      expert(tt, X.format, string.format("single frame size %d outside 1..%d (T2)",
                                         targ, C.SINGLE_MAX))
      return "single size=" .. targ, nil
    end
    if items then add(tt, F["chunk"], C.SINGLE_DATA, targ) end
    if st and st.open then abort(st, n, "interleaved") end
    if not trusted then return "single", nil end
    if targ == #tail then return "single", tail end  -- the tail starts at SINGLE_DATA
    return "single", ssub(tail, 1, targ)
  elseif ttype == C.T_FIRST then
    local total = u32(tail, C.T_TOTAL - C.HEAD)
    if items then
      add(tt, F["transfer_id"], C.T_ARG, 1)
      add_le(tt, F["total"], C.T_TOTAL, 4)
      add(tt, F["chunk"], C.FIRST_DATA, C.FIRST_CHUNK)
    end
    local limit = RX_LIMIT[dir] or C.MAX_TOTAL
    if total < C.FIRST_TOTAL_MIN or total > limit then
      expert(tt, X.format, string.format("first frame total %d outside %d..%d (T3, T6)",
                                         total, C.FIRST_TOTAL_MIN, limit))
      return "first ID=" .. targ .. " total=" .. total, nil
    end
    if st then
      abort(st, n, "new_first_frame")
      st.dead = nil
      st.open, st.id, st.total, st.len = true, targ, total, C.FIRST_CHUNK
      st.last, st.time, st.first, st.at = num, now, n, n
      st.parts[1] = ssub(tail, C.FIRST_DATA - C.HEAD + 1, C.FIRST_DATA - C.HEAD + C.FIRST_CHUNK)
      st.np = 1
      prev[n] = 0
    end
    return cols and "first ID=" .. NUMSTR[targ] .. " total=" .. total, nil
  elseif ttype == C.T_CONSECUTIVE then
    if items then
      add(tt, F["transfer_id"], C.T_ARG, 1)
      add(tt, F["chunk"], C.NEXT_DATA, C.CONSECUTIVE_CHUNK)
    end
    if st then
      local rest = st.open and st.total - st.len
      if not st.open then
        if targ ~= st.dead then note(n, "consecutive frame with no open transfer") end
      elseif targ ~= st.id then
        abort(st, n, "wrong_id")
      elseif num ~= (st.last + 1) % C.SEQ_MODULO then
        abort(st, n, "num_gap")
      elseif rest < C.CONSECUTIVE_CHUNK  -- a search, no copy
          and (sfind(tail, "[^\0]", rest + 1) or math.huge) <= C.CONSECUTIVE_CHUNK then
        abort(st, n, "bad_padding")  -- T4/T6a: the rest is zero; this is another transfer
      else
        local take = math.min(C.CONSECUTIVE_CHUNK, rest)
        st.np = st.np + 1
        st.parts[st.np] = take == #tail and tail or ssub(tail, 1, take)  -- from NEXT_DATA
        st.len = st.len + take
        st.last, st.time = num, now
        prev[n] = st.at
        st.at = n
        if st.len >= st.total then
          st.open = false
          done[n] = table.concat(st.parts, "", 1, st.np)
          local f = n
          while f ~= 0 do
            reasm_in[f] = n
            f = prev[f]
          end
        end
      end
    end
    return cols and CONS_INFO[targ], nil
  end
  expert(tt, X.format, string.format("transport type 0x%02X is not 0..2 (T1)", ttype))
  return string.format("transport 0x%02X", ttype), nil
end

-- the Tvb of the message being dissected, made only when an item needs its bytes
local MSG_DATA, FRAME_TVB
local function make_reassembled()
  return ByteArray.new(MSG_DATA, true):tvb("Reassembled EyeQ message")
end
local function make_single()
  return FRAME_TVB(C.SINGLE_DATA, #MSG_DATA):tvb()
end

-- the message a DATA frame completed or carried, its fragments, and its Info text
local function message_of(n, tvb, single, feed)
  local data, make = done[n], nil
  if data then
    local count, f = 0, n
    while f ~= 0 do
      count = count + 1
      f = prev[f]
    end
    local rt = add(ROOT, F["fragment_count"], nil, nil, count)
    if VIS or REF[F["fragment"]] ~= false then
      local list, f2 = {}, n
      while f2 ~= 0 do
        list[#list + 1] = f2
        f2 = prev[f2]
      end
      for i = #list, 1, -1 do add(rt, F["fragment"], nil, nil, list[i]) end
    end
    make = make_reassembled
  elseif reasm_in[n] then
    add(ROOT, F["reassembled_in"], nil, nil, reasm_in[n])
    return nil
  elseif single then
    data = single
    make = make_single
  else
    return nil
  end
  if feed and not REL.final and n <= SNIFF_RECORDS then evidence(data, n) end
  MSG_DATA, FRAME_TVB = data, tvb
  return dissect_message(data, make)
end

-- =============================================================================================
-- Link layer (decisions L1-L8) and the dissector
-- =============================================================================================
local ACK_INFO = {}  -- Info text prefix -> NUM -> the Info text of an ACK

function p.dissector(tvb, pinfo, tree)
  local n = pinfo.number
  if n <= prev_number then new_pass() end  -- a new pass: filters and columns may differ
  prev_number = n
  VIS = tree.visible
  local cols = COLS
  local columns  -- fetched only where columns are filled or not known yet (one object less)
  if VIS or cols == nil then
    columns = pinfo.cols
    cols = tostring(columns.info) ~= "(info)"  -- "(info)": this dissection fills no columns
    if not VIS then COLS = cols end
  end
  if cols then
    columns = columns or pinfo.cols
    columns.protocol = "EyeQ SPI"
  end
  local len = tvb:len()
  -- the direction from the pcapng interface; "?" when the capture has no interfaces; no field
  -- at all when this pass builds no tree
  local fi, dir = f_iface(), nil
  if fi then
    dir = DIRS[fi.value] or ("interface " .. fi.value)
  elseif f_frame() then
    dir = "?"
  else
    return len  -- no tree in this pass: nothing to add, nothing to feed
  end
  TVB, TVB_MAKE = tvb, nil
  -- a tree that is not shown needs no byte range (one object less per packet)
  ROOT, ROOT_TEXT = VIS and tree:add(p, tvb()) or tree:add(p), nil
  local seen = n <= last_fed
  local feed = not seen
  local sk = SKIP[G_FRAME]
  local link = VIS or not (sk or sk == nil and skip(G_FRAME))
  if dir ~= "?" and link then add(ROOT, F["dir"], nil, nil, dir) end
  if feed then
    last_fed = n
    if f_comment and not REL.final and n <= SNIFF_RECORDS then comment(n) end
  end
  if rel_notes[n] then expert(nil, X.note, rel_notes[n]) end
  local dirtext = DIRTEXT[dir] or (dir .. " ")
  if len ~= C.FRAME_SIZE then
    add(ROOT, F["bad_length"], nil, nil, true)
    add(ROOT, F["length"], nil, nil, len)
    expert(nil, X.bad_length, string.format("malformed transfer: %d bytes, not %d (L8)",
                                            len, C.FRAME_SIZE))
    if cols then columns.info = dirtext .. "bad length " .. len end
    return len
  end
  -- The header word, the CRC (L1) and a DATA frame's transport type and argument (T1). Only
  -- these bytes are copied into Lua, and the rest (the tail, which is also a consecutive
  -- frame's chunk as it stands) only when the frame's CRC covers it (a DATA frame): every
  -- copy feeds the garbage collector, which takes a third of the dissector's time.
  local h0, h1, h2, h3, c0, c1, ttype, targ = sbyte(tvb:raw(0, C.HEAD), 1, C.HEAD)
  local h = h0 + h1 * 256 + h2 * 65536 + h3 * 16777216
  local d = @HDR.D@
  local tail  -- the frame from byte HEAD on
  if not CRC_HEAD_ONLY[d] then tail = tvb:raw(C.HEAD) end
  local r = @HDR.R@
  local rsp = @HDR.RSP@
  local num = @HDR.NUM@
  local kind = KIND[d] or "INVALID"
  local ht
  if link then
    add(ROOT, F["frame_type"], 0, 4, kind)
    ht = add_le(ROOT, F["header"], 0, 4)
    add_le(ht, F["d"], 0, 4)
    add_le(ht, F["r"], 0, 4)
    add_le(ht, F["rsp"], 0, 4)
    add_le(ht, F["num"], 0, 4)
  end
  if kind == "INVALID" then
    expert(ht, X.format, string.format("D=0x%X is not a frame kind (L2)", d))
  end
  if r ~= 0 then expert(ht, X.format, string.format("R=0x%X, reserved must be 0 (L2)", r)) end
  local got = c0 + c1 * 256
  local crc, crc_ok
  if seen and not VIS then  -- checked when the frame was fed
    crc = crc_bad[n]
    crc_ok = crc == nil
    if crc_ok then crc = got end
  else
    crc = (CRC_BY_KIND[d] or CRC_OTHER)(tail, h0, h1, h2, h3, c0, c1, ttype, targ)
    crc_ok = crc == got
    if not crc_ok then crc_bad[n] = crc end
  end
  local ct
  if link then
    ct = add_le(ROOT, F["crc"], C.CRC_OFFSET, 2)
    add(ct, F["crc_computed"], C.CRC_OFFSET, 2, crc)
    add(ct, F["crc_ok"], C.CRC_OFFSET, 2, crc_ok)
  end
  if not crc_ok then
    expert(ct, X.bad_crc, string.format("CRC 0x%04X, computed 0x%04X (L3)", got, crc))
  end
  if kind == "NAK" then
    local nt = add(ROOT, F["nak_reason"], 0, 4, num)
    expert(nt, X.nak, string.format("NAK of NUM %d: %s", rsp, NAK_REASONS[num] or "unknown reason"))
  end
  local tinfo, name
  if kind == "DATA" then
    local single
    tinfo, single = dissect_transport(tail, pinfo, dir, num, crc_ok and r == 0, feed, n, cols,
                                      ttype, targ)
    local nt = notes[n]
    if nt then
      for i = 1, #nt do expert(nil, X.reassembly, nt[i]) end
    end
    if single or done[n] or reasm_in[n] then name = message_of(n, tvb, single, feed) end
  end
  if cols then
    local bad = crc_ok and "" or " [bad CRC]"
    if kind == "DATA" then
      if name then  -- one concatenation each, no intermediate string
        columns.info = dirtext .. "DATA NUM=" .. NUMSTR[num] .. " RSP=" .. NUMSTR[rsp] .. bad
                          .. " " .. tinfo .. ": " .. name
      else
        columns.info = dirtext .. "DATA NUM=" .. NUMSTR[num] .. " RSP=" .. NUMSTR[rsp] .. bad
                          .. " " .. tinfo
      end
    elseif kind == "ACK" then  -- a few thousand different texts: made once each
      local t = ACK_INFO[dirtext]
      if not t then
        t = {}
        ACK_INFO[dirtext] = t
      end
      local text = t[rsp]
      if not text then
        text = dirtext .. "ACK of NUM=" .. NUMSTR[rsp]
        t[rsp] = text
      end
      columns.info = text .. bad
    elseif kind == "NAK" then
      columns.info = dirtext .. "NAK of NUM=" .. NUMSTR[rsp] .. " "
                        .. (NAK_REASONS[num] or string.format("0x%03X", num)) .. bad
    else
      columns.info = dirtext .. kind .. string.format(" D=0x%X", d) .. bad
    end
  end
  return len
end
"""
