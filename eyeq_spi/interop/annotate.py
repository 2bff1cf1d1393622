"""SPI transfers of one channel -> sigrok annotation rows (link, transport, message, event),
computed by the dissector engine: the sigrok decoder repeats no codec. The texts are the same
functions of the dissector's records that ``tests/test_interop_sigrok.py`` applies to
``eyeq-spi dissect --json``, so the two can be compared frame by frame."""

from __future__ import annotations

from typing import Any

from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.dissect.engine import Dissector

ROWS = (("link", "Link frame"), ("transport", "Transport"), ("message", "Message"),
        ("event", "Event"))
LINK, TRANSPORT, MESSAGE, EVENT = range(4)
_KEEP = 256  # transfers whose sample span is remembered (a message spans at most 70)


def link_text(record: dict[str, Any]) -> str:
    if "length" in record:
        return f"INVALID length {record['length']}"
    crc = "ok" if record["crc_ok"] else "BAD"
    text = f"{record['frame_type']} NUM={record['num']} RSP={record['rsp']} CRC {crc}"
    if record["nak_reason"] is not None:
        text += f" reason=0x{record['nak_reason']:03X}"
    return text


def transport_text(record: dict[str, Any]) -> str | None:
    if record["frame_type"] != "DATA" or record["transport"] is None:
        return None
    tid = record["transfer_id"]
    return str(record["transport"]) + ("" if tid is None else f" id={tid}")


def message_text(record: dict[str, Any]) -> str:
    text = f"{record['protocol']} {record['name'] or '?'} {record['length']} B"
    if record["errors"]:
        text += f" ({len(record['errors'])} errors: {record['errors'][0]})"
    return text


def event_text(record: dict[str, Any]) -> str:
    return str(record["type"])


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
        for record in self.dis.feed(Transfer(time, self.direction, bytes(data))):
            kind = record["kind"]
            if kind == "frame":
                out.append((ss, es, LINK, link_text(record)))
                text = transport_text(record)
                if text is not None:
                    out.append((ss, es, TRANSPORT, text))
            elif kind == "message":
                first = next((f for f in record["frames"] if f in self._spans), index)
                out.append((self._spans[first][0], es, MESSAGE, message_text(record)))
            else:
                out.append((ss, es, EVENT, event_text(record)))
        return out
