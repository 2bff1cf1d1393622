"""Generate the Wireshark Lua dissector of eyeq-spi captures from ``specs/`` (docs/wireshark.md).

``generate_lua()`` returns one self-contained Lua file for Wireshark 4.0+ (Lua 5.2) registered for
the capture's link type (``specs/capture.yaml``), from ``specs/link.yaml`` (L1-L8, T1-T6),
``specs/mesp.yaml`` (M1-M3) and every layout of every SW release; the dissector picks each
capture's release at run time (decision D4)."""

from __future__ import annotations

import re

from eyeq_spi.capture.pcapng_io import release_sniff_transfers
from eyeq_spi.catalog.link import link_spec
from eyeq_spi.catalog.messages import SwKey, sw_release_text
from eyeq_spi.catalog.schema import sw_key
from eyeq_spi.codec.mesp import MESP_PROTOCOL, REPLY_BIT, TAG_MASK
from eyeq_spi.codec.message import DASP_PROTOCOL, MessageCodec
from eyeq_spi.errors import SpecError
from eyeq_spi.link.frame import FrameCodec
from eyeq_spi.wireshark.lua_app import MESP_PARAM_FIELD, AppGenerator
from eyeq_spi.wireshark.lua_common import (
    FieldRegistry,
    ValueStrings,
    int_field_args,
    lua_int,
    lua_str,
    value_table,
)
from eyeq_spi.wireshark.lua_crc import CRC_RUNTIME, CRC_SELFTEST, crc_functions
from eyeq_spi.wireshark.lua_crc import HEAD as CRC_HEAD
from eyeq_spi.wireshark.lua_items import RUNTIME_ITEMS
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


def header_expr(word: str, shift: int, mask: int) -> str:
    """Lua arithmetic for ``(word >> shift) & mask`` of a non-negative integer below 2^32, for
    a mask of low bits: exact in Lua 5.2's doubles and with no call into the ``bit`` library,
    which costs a C call per operation in every frame."""
    if mask & (mask + 1):
        raise SpecError(f"specs/link.yaml frame.header: mask 0x{mask:X} is not a run of low bits")
    value = word if shift == 0 else f"({word} - {word} % {1 << shift}) / {1 << shift}"
    return f"{value} % {mask + 1}"


def inline_constants(text: str, inline: dict[str, str]) -> str:
    """The fixed Lua ``text`` with every constant of ``inline`` (``C.NAME``, ``@HDR.X@``)
    written as its value: a literal costs nothing per frame, a look-up in ``C`` a hashed
    table access."""
    def value(match: re.Match[str]) -> str:
        key = match.group(0)
        if key not in inline:
            raise SpecError(f"the Lua runtime uses {key}, which the generator does not define")
        return inline[key]
    return re.sub(r"\bC\.[A-Z_]+\b|@HDR\.[A-Z]+@", value, text)


def _header_fields() -> dict[str, tuple[int, int]]:
    """name -> (shift, mask) of the header word (L1), read off the link's frame codec."""
    codec = FrameCodec()
    masks = codec.unpack_header(0xFFFFFFFF)
    out = {}
    for index, name in enumerate(("D", "R", "RSP", "NUM")):
        one = [0, 0, 0, 0]
        one[index] = 1
        out[name] = (codec.pack_header(*one).bit_length() - 1, masks[index])
    return out


VERSIONS_FUNCTION = "GetEyeQVersions"  # its reply reports the EyeQ's SW release (§7.1.1.1.5)
BOOT_MESSAGE, BOOT_VERSION = "EYEQ_BOOT_STATUS_MSG", "ApplicationVersion"  # §7.1.5.3
BASE_DIAG_MESSAGE = "EYEQ_BASE_DIAG_STATUS_MSG"  # §7.1.4.1: eyeqSwVersionMajor/Minor
SW_MAJOR, SW_MINOR = "eyeqSwVersionMajor", "eyeqSwVersionMinor"


class LuaGenerator:
    def __init__(self, sw: str | None = None) -> None:
        newest = MessageCodec()
        self.cat = newest.cat
        self.fixed: SwKey | None = self.cat.sw(sw) if sw is not None else None
        self.codecs = {k: MessageCodec(k, self.cat)
                       for k in sorted(self.cat.sw_versions, key=sw_key)}
        self.releases = list(self.codecs)
        self.spec = link_spec()
        self.capture = dict(self.cat.raw["capture.yaml"]["capture"])
        self.fields = FieldRegistry()
        self.vs = ValueStrings()
        self.app = AppGenerator(self.codecs, self.fields, self.vs)
        self.inline: dict[str, str] = {}  # constant -> its Lua text (set by constants())

    def release_constants(self) -> list[str]:
        """Releases, the preference's choices and where the EyeQ reports its release."""
        rel = [sw_release_text(k) for k in self.releases]
        lines = ["local RELEASES = {" + ", ".join(lua_str(r) for r in rel) + "}",
                 f"local NEWEST = {self.releases.index(self.cat.default_sw) + 1}",
                 f"local SNIFF_RECORDS = {release_sniff_transfers()}"]
        fixed = 0 if self.fixed is None else self.releases.index(self.fixed) + 1
        lines.append(f"local PREF_DEFAULT = {fixed}")
        choices = ['{1, "auto", 0}'] + [
            f"{{{i + 1}, {lua_str(r)}, {i}}}" for i, r in enumerate(rel, 1)]
        lines.append("local PREF_CHOICES = {" + ", ".join(choices) + "}")
        fn = next(function for function in self.cat.mesp if function.name == VERSIONS_FUNCTION)
        off, where = 0, {}
        for prm in fn.reply:
            if prm.type not in MESP_PARAM_FIELD:
                break
            where[prm.name] = off
            off += MESP_PARAM_FIELD[prm.type][1]
        if SW_MAJOR not in where or SW_MINOR not in where:
            raise SpecError(f"specs/mesp.yaml {fn.name}: the reply does not lead with "
                            f"{SW_MAJOR}/{SW_MINOR}")
        lines.append(f"local VERSIONS = {{key = {lua_int(fn.service * 256 + fn.function)}, "
                     f"major = {where[SW_MAJOR]}, minor = {where[SW_MINOR]}}}")
        boot = self.cat.message(BOOT_MESSAGE)
        diag = self.cat.message(BASE_DIAG_MESSAGE)
        boot_at: dict[int, int] = {}
        diag_at: set[tuple[int, int]] = set()
        for codec in self.codecs.values():
            lay = codec.layout(boot)
            boot_at[1 + lay.size] = 1 + next(info.offset for info in lay.fields
                                             if info.name == BOOT_VERSION)
            if diag.exists_in(codec.sw):
                offsets = {x.name: x.offset for x in codec.layout(diag).fields}
                diag_at.add((4 + offsets[SW_MAJOR], 4 + offsets[SW_MINOR]))
        if len(diag_at) != 1:
            raise SpecError(f"specs/structs {BASE_DIAG_MESSAGE}: {SW_MAJOR}/{SW_MINOR} move "
                            "between releases")
        major, minor = diag_at.pop()
        lines.append(f"local BOOT = {{id = {lua_int(boot.data_id)}, at = "
                     + "{" + ", ".join(f"[{n}] = {o}" for n, o in sorted(boot_at.items()))
                     + "}}")
        lines.append(f"local BASE_DIAG = {{id = {lua_int(diag.data_id)}, major = {major}, "
                     f"minor = {minor}}}")
        return lines

    # -- constants ---------------------------------------------------------------------------
    def constants(self) -> list[str]:
        spec = self.spec
        frame, crc, tr = spec["frame"], spec["crc"], spec["transport"]
        if crc["reflect"]:
            raise SpecError("specs/link.yaml crc.reflect: the Lua generator computes an "
                            "unreflected CRC only")
        if int(crc["poly"]) > 0xFFFF or int(crc["init"]) > 0xFFFF:
            raise SpecError("specs/link.yaml crc.poly, crc.init: the Lua generator computes a "
                            "CRC-16 only")
        data_offset = int(frame["data_offset"])
        types = tr["types"]
        consts = {
            "FRAME_SIZE": int(frame["size"]),
            "CRC_OFFSET": int(frame["crc_offset"]),
            "CRC_POLY": int(crc["poly"]),
            "CRC_INIT": int(crc["init"]),
            "CRC_XOROUT": int(crc["xorout"]),
            "CRC_CHECK": int(crc["check"]),
            "SEQ_MODULO": int(spec["sequence"]["modulo"]),
            # T1-T4: byte 6 type, byte 7 size or ID, a first frame's total is a uint32 LE
            "T_TYPE": data_offset,
            "T_ARG": data_offset + 1,
            "T_TOTAL": data_offset + 2,
            "HEAD": data_offset + 2,  # bytes read before the rest of a frame (lua_crc.HEAD)
            "SINGLE_DATA": data_offset + 2,
            "FIRST_DATA": data_offset + 6,
            "NEXT_DATA": data_offset + 2,
            "T_SINGLE": int(types["single"]),
            "T_FIRST": int(types["first"]),
            "T_CONSECUTIVE": int(types["consecutive"]),
            "SINGLE_MAX": int(tr["single_max"]),
            "FIRST_CHUNK": int(tr["first_chunk"]),
            "CONSECUTIVE_CHUNK": int(tr["consecutive_chunk"]),
            "FIRST_TOTAL_MIN": int(tr["first_total_min"]),
            "MAX_TOTAL": int(tr["max_total"]),
        }
        # the runtime reads these with one call
        if consts["CRC_OFFSET"] != 4 or consts["HEAD"] != CRC_HEAD \
                or consts["NEXT_DATA"] != CRC_HEAD or consts["SINGLE_DATA"] != CRC_HEAD:
            raise SpecError("specs/link.yaml frame: the Lua dissector expects the CRC right "
                            "after the 4-byte header, then transport type and argument, then "
                            "the data")
        if consts["FIRST_DATA"] + consts["FIRST_CHUNK"] > consts["FRAME_SIZE"]:
            raise SpecError("specs/link.yaml transport.first_chunk: does not fit the frame")
        if consts["NEXT_DATA"] + consts["CONSECUTIVE_CHUNK"] > consts["FRAME_SIZE"]:
            raise SpecError("specs/link.yaml transport.consecutive_chunk: does not fit the frame")
        lines = ["local C = {"]
        lines += [f"  {k} = {lua_int(v) if k.startswith('CRC_') else v},"
                  for k, v in consts.items()]
        timeout = repr(float(tr["reassembly_timeout"]))
        lines.append(f"  REASSEMBLY_TIMEOUT = {timeout},")
        lines.append("}")
        hdr = _header_fields()
        self.inline = {f"C.{k}": str(v) for k, v in consts.items()}
        self.inline["C.REASSEMBLY_TIMEOUT"] = timeout
        self.inline.update({f"@HDR.{k}@": header_expr("h", sh, m) for k, (sh, m) in hdr.items()})
        kinds = {int(v): str(k) for k, v in spec["kinds"].items()}
        lines.append(f"local KIND = {value_table(kinds)}")
        lines.append("local NAK_REASONS = " + value_table(
            {int(k): str(v["name"]) for k, v in spec["nak_reasons"].items()}))
        lines.append("local TTYPE = " + value_table({int(v): str(k) for k, v in types.items()}))
        dirs = {int(i["id"]): str(i["name"]) for i in self.capture["interfaces"]}
        if set(dirs.values()) != set(RECEIVER):
            raise SpecError(f"specs/capture.yaml capture.interfaces: {sorted(dirs.values())} "
                            "are not h2e/e2h")
        lines.append(f"local DIRS = {value_table(dirs)}")
        lines.append('local DIRTEXT = {["?"] = ""}  -- the Info column\'s prefix per direction')
        lines.append("for _, name in pairs(DIRS) do DIRTEXT[name] = name .. \" \" end")
        limits = ", ".join(f"{name} = {int(tr['receive_limit'][RECEIVER[name]])}"
                           for name in sorted(RECEIVER))
        lines.append(f"local RX_LIMIT = {{{limits}}}")
        lines.append(f"local DASP_PROTOCOL = {lua_int(DASP_PROTOCOL)}")
        lines.append(f"local MESP_PROTOCOL = {lua_int(MESP_PROTOCOL)}")
        widths = ", ".join(f"{k} = {w}" for k, (_, w) in MESP_PARAM_FIELD.items())
        lines.append(f"local MESP_WIDTH = {{{widths}}}")
        return lines

    def crc(self) -> list[str]:
        cov = self.spec["crc"]["coverage"]
        kinds = self.spec["kinds"]
        by_kind = {int(kinds[k]): [(int(a), int(b)) for a, b in cov[k]] for k in kinds}
        other = [(int(a), int(b)) for a, b in cov["other"]]
        return [CRC_RUNTIME, *crc_functions(by_kind, other), CRC_SELFTEST]

    # -- fixed fields --------------------------------------------------------------------------
    def link_fields(self) -> None:
        add = self.fields.add
        spec = self.spec
        hdr = _header_fields()
        kinds = {int(v): str(k) for k, v in spec["kinds"].items()}
        naks = {int(k): str(v["name"]) for k, v in spec["nak_reasons"].items()}
        types = {int(v): str(k) for k, v in spec["transport"]["types"].items()}
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
        add("sw", "string", lua_str("SW release"))
        add("sw_source", "string", lua_str("SW release from"))

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
            raise SpecError(f"specs/capture.yaml capture.link_type: {link_type} is not "
                            "LINKTYPE_USER0..15 (147..162)")
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
        spare_mask = 0xFF & ~(TAG_MASK | REPLY_BIT)
        parts = [
            f"-- EyeQ4 SPI dissector for Wireshark 4.0+ (Lua 5.2), generated by\n"
            f"-- eyeq_spi.wireshark.lua_gen from specs/ for SW "
            f"{', '.join(sw_release_text(k) for k in self.releases)}. Do not edit: "
            f"regenerate.\n"
            f"-- Usage: tshark -X lua_script:eyeq_spi.lua -r capture.pcapng "
            f"(or copy to the plugins folder)",
            'local p = Proto("eyeq_spi", "EyeQ4 SPI")',
            "local band, bxor, lshift, rshift = bit.band, bit.bxor, bit.lshift, bit.rshift",
            "",
            "-- constants from specs/link.yaml, specs/capture.yaml and the codec",
            *self.constants(),
            *self.release_constants(),
            *self.crc(),
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
            "local MSG, DASP_R, OTHER_R, SIZES, MESP = {}, {}, {}, {}, {}",
            f"local MESP_REPLY_MASK = {lua_int(REPLY_BIT)}",
            f"local MESP_TAG_SPARE = {lua_int(spare_mask)}",
            *self.app.out.messages,
            inline_constants(RUNTIME_ITEMS, self.inline),
            inline_constants(RUNTIME, self.inline),
            self.registration(),
            "",
        ]
        return "\n".join(parts)


def generate_lua(sw: str | None = None) -> str:
    """The whole dissector as Lua source for every release; ``sw`` is the default of its
    ``eyeq_spi.sw`` preference, which overrides what a capture says (default: automatic)."""
    return LuaGenerator(sw).generate()
