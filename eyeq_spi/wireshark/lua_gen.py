"""Generate the Wireshark Lua dissector of eyeq-spi captures from ``specs/``.

``generate_lua()`` returns one self-contained Lua file for Wireshark/tshark 4.0 and later (Lua 5.2,
bit operations through Wireshark's ``bit`` library). It registers ``eyeq_spi`` on the
``wtap_encap`` table for the capture's link type (``specs/capture.yaml``: LINKTYPE_USER0), so a
capture opens with no set-up::

    tshark -X lua_script:eyeq_spi.lua -r capture.pcapng

Sources: the link and transport constants from ``specs/link.yaml`` (L1-L8, T1-T6), interfaces
from ``specs/capture.yaml``, MESP from ``specs/mesp.yaml`` (M1-M3) and every DASP/0x41/0x10 layout
from :class:`eyeq_spi.codec.message.MessageCodec` for one SW version (the newest by default,
D4). Fixed filter names: ``eyeq_spi.dir``, ``.frame_type``, ``.num``, ``.rsp``, ``.crc``,
``.crc_ok``, ``.nak_reason``, ``.transport``, ``.transfer_id``, ``.total``, ``.size``,
``.bad_length``; ``eyeq_spi.mesp.*``, ``eyeq_spi.dasp.*``; payload members
``eyeq_spi.<struct>.<member>`` (see :mod:`eyeq_spi.wireshark.lua_app`).
"""

from __future__ import annotations

from typing import Any

from eyeq_spi.codec.mesp import MESP_PROTOCOL
from eyeq_spi.codec.message import DASP_PROTOCOL, MessageCodec
from eyeq_spi.spec.link import link_spec
from eyeq_spi.wireshark.lua_app import MESP_PARAM_FIELD, AppGenerator
from eyeq_spi.wireshark.lua_common import (
    FieldRegistry,
    ValueStrings,
    int_field_args,
    lua_int,
    lua_str,
    value_table,
)
from eyeq_spi.wireshark.lua_runtime import RUNTIME

LINKTYPE_USER0 = 147  # LINKTYPE_USER0..USER15 are 147..162 = wtap.USER0..USER15
RECEIVER = {"h2e": "eyeq", "e2h": "host"}  # who receives each SPI channel (receive limits, T6)

EXPERTS = [
    # key, summary, group, severity
    ("bad_length", "Transfer is not 128 bytes (L8)", "MALFORMED", "ERROR"),
    ("bad_crc", "CRC mismatch (L3)", "CHECKSUM", "ERROR"),
    ("format", "Format error (L2, T1-T3)", "MALFORMED", "ERROR"),
    ("nak", "NAK", "SEQUENCE", "WARN"),
    ("reassembly", "Reassembly event (T6)", "REASSEMBLE", "WARN"),
    ("length_mismatch", "Payload length mismatch (D3)", "MALFORMED", "ERROR"),
    ("malformed", "Malformed message", "MALFORMED", "ERROR"),
    ("unknown", "Unknown message", "UNDECODED", "WARN"),
    ("note", "Protocol note", "PROTOCOL", "NOTE"),
]


def _header_fields(frame: dict[str, Any]) -> dict[str, tuple[int, int]]:
    """name -> (shift, mask) of the header word (L1), as eyeq_spi.link.frame computes them."""
    header = frame["header"]
    if header["word"] != "uint32le":
        raise ValueError(f"header word {header['word']!r}: only uint32le is supported")
    fields = [(str(n), int(w)) for n, w in header["fields"]]
    if header["bit_order"] == "msb_first":
        fields = fields[::-1]
    elif header["bit_order"] != "lsb_first":
        raise ValueError(f"unknown header bit order {header['bit_order']!r}")
    out: dict[str, tuple[int, int]] = {}
    pos = 0
    for name, width in fields:
        out[name] = (pos, (1 << width) - 1)
        pos += width
    if pos != 32 or set(out) != {"D", "R", "RSP", "NUM"}:
        raise ValueError("the header word must hold exactly D, R, RSP and NUM in 32 bits")
    return out


def _ranges(ranges: list[list[int]]) -> str:
    return "{" + ", ".join(f"{{{int(a)}, {int(b)}}}" for a, b in ranges) + "}"


class LuaGenerator:
    def __init__(self, sw: str | None = None) -> None:
        self.codec = MessageCodec(sw)
        self.spec = link_spec()
        self.capture = dict(self.codec.cat.raw["capture.yaml"]["capture"])
        self.fields = FieldRegistry()
        self.vs = ValueStrings()
        self.app = AppGenerator(self.codec, self.fields, self.vs)

    # -- constants ---------------------------------------------------------------------------
    def constants(self) -> list[str]:
        s = self.spec
        frame, crc, tr = s["frame"], s["crc"], s["transport"]
        if crc["reflect"]:
            raise ValueError("a reflected CRC is not supported by the Lua generator")
        if int(crc["poly"]) > 0xFFFF or int(crc["init"]) > 0xFFFF:
            raise ValueError("the Lua generator computes a CRC-16 only")
        d = int(frame["data_offset"])
        types = tr["types"]
        c = {
            "FRAME_SIZE": int(frame["size"]),
            "CRC_OFFSET": int(frame["crc_offset"]),
            "CRC_POLY": int(crc["poly"]),
            "CRC_INIT": int(crc["init"]),
            "CRC_XOROUT": int(crc["xorout"]),
            "CRC_CHECK": int(crc["check"]),
            "SEQ_MODULO": int(s["sequence"]["modulo"]),
            # T1-T4: byte 6 type, byte 7 size or ID, a first frame's total is a uint32 LE
            "T_TYPE": d,
            "T_ARG": d + 1,
            "T_TOTAL": d + 2,
            "SINGLE_DATA": d + 2,
            "FIRST_DATA": d + 6,
            "NEXT_DATA": d + 2,
            "T_SINGLE": int(types["single"]),
            "T_FIRST": int(types["first"]),
            "T_CONSECUTIVE": int(types["consecutive"]),
            "SINGLE_MAX": int(tr["single_max"]),
            "FIRST_CHUNK": int(tr["first_chunk"]),
            "CONSECUTIVE_CHUNK": int(tr["consecutive_chunk"]),
            "FIRST_TOTAL_MIN": int(tr["first_total_min"]),
            "MAX_TOTAL": int(tr["max_total"]),
        }
        if c["FIRST_DATA"] + c["FIRST_CHUNK"] > c["FRAME_SIZE"]:
            raise ValueError("first_chunk does not fit the frame")
        if c["NEXT_DATA"] + c["CONSECUTIVE_CHUNK"] > c["FRAME_SIZE"]:
            raise ValueError("consecutive_chunk does not fit the frame")
        lines = ["local C = {"]
        lines += [f"  {k} = {lua_int(v) if k.startswith('CRC_') else v}," for k, v in c.items()]
        lines.append(f"  REASSEMBLY_TIMEOUT = {float(tr['reassembly_timeout'])!r},")
        lines.append("}")
        hdr = _header_fields(frame)
        lines.append("local HDR = {" + ", ".join(
            f"{k} = {{{sh}, {lua_int(m)}}}" for k, (sh, m) in hdr.items()) + "}")
        kinds = {int(v): str(k) for k, v in s["kinds"].items()}
        lines.append(f"local KIND = {value_table(kinds)}")
        cov = crc["coverage"]
        by_kind = ", ".join(f"[{lua_int(int(s['kinds'][k]))}] = {_ranges(cov[k])}"
                            for k in s["kinds"])
        lines.append(f"local COVER = {{{by_kind}}}")
        lines.append(f"local COVER_OTHER = {_ranges(cov['other'])}")
        lines.append("local NAK_REASONS = " + value_table(
            {int(k): str(v["name"]) for k, v in s["nak_reasons"].items()}))
        lines.append("local TTYPE = " + value_table({int(v): str(k) for k, v in types.items()}))
        dirs = {int(i["id"]): str(i["name"]) for i in self.capture["interfaces"]}
        if set(dirs.values()) != set(RECEIVER):
            raise ValueError(f"capture interfaces {sorted(dirs.values())} are not h2e/e2h")
        lines.append(f"local DIRS = {value_table(dirs)}")
        limits = ", ".join(f"{name} = {int(tr['receive_limit'][RECEIVER[name]])}"
                           for name in sorted(RECEIVER))
        lines.append(f"local RX_LIMIT = {{{limits}}}")
        lines.append(f"local SW = {lua_str(self.codec.sw)}")
        lines.append(f"local DASP_PROTOCOL = {lua_int(DASP_PROTOCOL)}")
        mesp_protocol = int(self.codec.cat.raw["mesp.yaml"]["mesp"]["protocol"])
        if mesp_protocol != MESP_PROTOCOL:
            raise ValueError("specs/mesp.yaml protocol disagrees with eyeq_spi.codec.mesp")
        lines.append(f"local MESP_PROTOCOL = {lua_int(mesp_protocol)}")
        widths = ", ".join(f"{k} = {w}" for k, (_, w) in MESP_PARAM_FIELD.items())
        lines.append(f"local MESP_WIDTH = {{{widths}}}")
        return lines

    # -- fixed fields --------------------------------------------------------------------------
    def link_fields(self) -> None:
        add = self.fields.add
        s = self.spec
        hdr = _header_fields(s["frame"])
        kinds = {int(v): str(k) for k, v in s["kinds"].items()}
        naks = {int(k): str(v["name"]) for k, v in s["nak_reasons"].items()}
        types = {int(v): str(k) for k, v in s["transport"]["types"].items()}
        add("dir", "string", lua_str("Direction"))
        add("bad_length", "bool", lua_str("Bad length"))
        add("length", "uint32", lua_str("Transfer length"), "base.DEC")
        add("frame_type", "string", lua_str("Frame type"))
        add("header", "uint32", lua_str("Header word"), "base.HEX")
        labels = {"D": ("d", "D (kind)", "base.HEX", self.vs.add("link.frame_kind", kinds)),
                  "R": ("r", "R (reserved)", "base.DEC", None),
                  "RSP": ("rsp", "RSP", "base.DEC", None),
                  "NUM": ("num", "NUM", "base.DEC", None)}
        for name, (key, label, base, vs) in labels.items():
            shift, mask = hdr[name]
            add(key, "uint32", *int_field_args(label, base, vs, mask << shift, None))
        add("crc", "uint16", lua_str("CRC"), "base.HEX")
        add("crc_computed", "uint16", lua_str("Computed CRC"), "base.HEX")
        add("crc_ok", "bool", lua_str("CRC OK"))
        add("nak_reason", "uint16", lua_str("NAK reason"), "base.HEX",
            self.vs.add("link.nak_reason", naks))
        add("transport", "string", lua_str("Transport"))
        add("transport_type", "uint8", lua_str("Transport type"), "base.HEX",
            self.vs.add("link.transport_type", types))
        add("size", "uint8", lua_str("Size"), "base.DEC")
        add("transfer_id", "uint8", lua_str("Transfer ID"), "base.DEC")
        add("total", "uint32", lua_str("Total"), "base.DEC")
        add("chunk", "bytes", lua_str("Message bytes"))
        add("fragment_count", "uint32", lua_str("Frames in message"), "base.DEC")
        add("fragment", "framenum", lua_str("Frame of message"))
        add("reassembled_in", "framenum", lua_str("Reassembled in"))
        add("msg", "none", lua_str("Message"))
        add("msg_length", "uint32", lua_str("Message length"), "base.DEC")
        add("app_protocol", "string", lua_str("Application protocol"))
        add("message", "string", lua_str("Message name"))
        add("msg_id", "uint8", lua_str("Message ID"), "base.HEX")

    def dasp_fields(self) -> None:
        add = self.fields.add
        add("dasp.protocol", "uint8", lua_str("Protocol"), "base.HEX")
        add("dasp.data_id", "uint8", lua_str("Data ID"), "base.HEX",
            self.vs.add("dasp_data_id", self.app.data_id_names))
        add("dasp.counter", "uint8", lua_str("Counter"), "base.DEC")
        add("dasp.reserved", "uint8", lua_str("Reserved"), "base.HEX")

    def registration(self) -> str:
        link_type = int(self.capture["link_type"])
        user = link_type - LINKTYPE_USER0
        if not 0 <= user <= 15:
            raise ValueError(f"link type {link_type} is not LINKTYPE_USER0..15")
        return f'DissectorTable.get("wtap_encap"):add(wtap.USER{user}, p)'

    # -- whole file ----------------------------------------------------------------------------
    def generate(self) -> str:
        self.link_fields()
        self.app.messages()
        self.app.mesp_fields()
        self.dasp_fields()
        experts = ["local X = {"]
        for key, summary, group, severity in EXPERTS:
            experts.append(f"  {key} = ProtoExpert.new({lua_str('eyeq_spi.expert.' + key)}, "
                           f"{lua_str(summary)}, expert.group.{group}, "
                           f"expert.severity.{severity}),")
        experts.append("}")
        counter_mask, reply_mask = self.app.mesp_masks
        spare_mask = 0xFF & ~(counter_mask | reply_mask)
        parts = [
            f"-- EyeQ4 SPI dissector for Wireshark 4.0+ (Lua 5.2), generated by\n"
            f"-- eyeq_spi.wireshark.lua_gen from specs/ for {self.codec.sw}. Do not edit: "
            f"regenerate.\n"
            f"-- Usage: tshark -X lua_script:eyeq_spi.lua -r capture.pcapng "
            f"(or copy to the plugins folder)",
            'local p = Proto("eyeq_spi", "EyeQ4 SPI")',
            "local band, bxor, lshift, rshift = bit.band, bit.bxor, bit.lshift, bit.rshift",
            "",
            "-- constants from specs/link.yaml, specs/capture.yaml and the codec",
            *self.constants(),
            "",
            "-- value_strings: specs/enums, link.yaml, mesp.yaml, messages.yaml",
            "local E = {}",
            self.vs.render(),
            "",
            "-- ProtoFields: fixed ones, then eyeq_spi.<struct>.<member> for every payload member",
            "local F = {}",
            "local FIELD_LIST = {}",
            "local function pf(f)\n  FIELD_LIST[#FIELD_LIST + 1] = f\n  return f\nend",
            self.fields.render(),
            "p.fields = FIELD_LIST",
            "",
            *experts,
            "p.experts = {" + ", ".join(f"X.{k[0]}" for k in EXPERTS) + "}",
            "",
            "-- struct layouts (MessageCodec, decision D2)",
            "local S = {}",
            *self.app.out.structs,
            "",
            "-- messages (decision A; specs/messages.yaml, specs/mesp.yaml)",
            "local DASP, OTHER, MESP = {}, {}, {}",
            f"local MESP_REPLY_MASK = {lua_int(reply_mask)}",
            f"local MESP_TAG_SPARE = {lua_int(spare_mask)}",
            *self.app.out.messages,
            RUNTIME,
            self.registration(),
            "",
        ]
        return "\n".join(parts)


def generate_lua(sw: str | None = None) -> str:
    """The whole dissector as Lua source, for SW version ``sw`` (default: the newest)."""
    return LuaGenerator(sw).generate()
