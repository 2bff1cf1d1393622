"""SPI transfers of one channel -> sigrok annotation rows (link, transport, message, event),
computed by the dissector engine: the sigrok decoder repeats no codec. The texts are the same
functions of the dissector's records that ``tests/test_interop_sigrok.py`` applies to
``eyeq-spi dissect --json``, so the two can be compared frame by frame."""

from __future__ import annotations

from typing import Any

from eyeq_spi.capture.pcapng_io import Record
from eyeq_spi.dissect.engine import Dissector

ROWS = (("link", "Link frame"), ("transport", "Transport"), ("message", "Message"),
        ("event", "Event"))
LINK, TRANSPORT, MESSAGE, EVENT = range(4)
_KEEP = 256  # transfers whose sample span is remembered (a message spans at most 70)


def link_text(r: dict[str, Any]) -> str:
    if "length" in r:
        return f"INVALID length {r['length']}"
    crc = "ok" if r["crc_ok"] else "BAD"
    text = f"{r['frame_type']} NUM={r['num']} RSP={r['rsp']} CRC {crc}"
    if r["nak_reason"] is not None:
        text += f" reason=0x{r['nak_reason']:03X}"
    return text


def transport_text(r: dict[str, Any]) -> str | None:
    if r["frame_type"] != "DATA" or r["transport"] is None:
        return None
    tid = r["transfer_id"]
    return str(r["transport"]) + ("" if tid is None else f" id={tid}")


def message_text(r: dict[str, Any]) -> str:
    text = f"{r['protocol']} {r['name'] or '?'} {r['length']} B"
    if r["errors"]:
        text += f" ({len(r['errors'])} errors: {r['errors'][0]})"
    return text


def event_text(r: dict[str, Any]) -> str:
    return str(r["type"])


Annotation = tuple[int, int, int, str]
"""(start sample, end sample, row, text)"""


def short_texts(row: int, text: str) -> list[str]:
    """The text, then shorter forms for a zoomed-out PulseView (first word, its initial)."""
    words = text.split()
    if row == MESSAGE and len(words) > 1:
        return [text, words[1], words[0]]
    if row == LINK and len(words) > 1:
        return [text, f"{words[0]} {words[1]}", words[0][0]]
    return [text, words[0]] if len(words) > 1 else [text]


class Annotator:
    """Feed the transfers of one SPI channel; get annotations back."""

    def __init__(self, direction: str | None, sw: str | None = None) -> None:
        self.direction = direction
        self.dis = Dissector(sw or None)
        self._spans: dict[int, tuple[int, int]] = {}

    def transfer(self, data: bytes, ss: int, es: int, time: float | None) -> list[Annotation]:
        out: list[Annotation] = []
        index = self.dis.index
        self._spans[index] = (ss, es)
        self._spans.pop(index - _KEEP, None)
        for r in self.dis.feed(Record(time, self.direction, bytes(data))):
            kind = r["kind"]
            if kind == "frame":
                out.append((ss, es, LINK, link_text(r)))
                t = transport_text(r)
                if t is not None:
                    out.append((ss, es, TRANSPORT, t))
            elif kind == "message":
                first = next((f for f in r["frames"] if f in self._spans), index)
                out.append((self._spans[first][0], es, MESSAGE, message_text(r)))
            else:
                out.append((ss, es, EVENT, event_text(r)))
        return out
