"""Which channel of a log is the camera (decision C10).

A vehicle log holds the camera's frames beside other ECUs' (radars, the vehicle's own buses),
and those may use IDs of the protocol (a radar's 0x650, vehicle frames 0x773 and 0x778 that are
Next_Lane slots of ExtLogData2). A channel looks like a camera when it carries most of the
protocol's periodic messages (those without slots, which a camera sends whatever it sees) at
their DLC (or a short DLC that holds every signal, C8). The camera's channel is the one that
looks most so; frames of other channels are other nodes' traffic.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import Any

from eyeq_spi.can.decode import CanDecoder

PREFIX_FRAMES = 5_000  # frames of a log looked at to find the camera before decoding it


@dataclass(frozen=True)
class ChannelVerdict:
    channel: str | None
    periodic_seen: int  # the protocol's periodic messages on the channel at a right DLC
    periodic_total: int
    wrong_dlc: tuple[int, ...]  # protocol IDs on the channel with a DLC that is not theirs

    @property
    def looks_like_camera(self) -> bool:
        return self.periodic_seen * 2 > self.periodic_total and \
            len(self.wrong_dlc) * 4 < max(1, self.periodic_seen)

    def describe(self) -> str:
        dlc = "" if not self.wrong_dlc else \
            f", wrong DLC on {', '.join(f'0x{i:X}' for i in self.wrong_dlc)}"
        return f"{self.periodic_seen} of the {self.periodic_total} periodic messages{dlc}"


class ChannelCensus:
    """Per channel, the protocol IDs seen and whether their DLC fits."""

    def __init__(self, decoder: CanDecoder) -> None:
        self.decoder = decoder
        self.periodic = frozenset(fid for fid, d in decoder.by_id.items()
                                  if d.spec.slots is None)
        self.good: defaultdict[str | None, set[int]] = defaultdict(set)
        self.bad: defaultdict[str | None, set[int]] = defaultdict(set)
        self.frames: defaultdict[str | None, int] = defaultdict(int)

    def add(self, channel: str | None, fid: int, dlc: int, extended: bool = False,
            count: int = 1) -> None:
        self.frames[channel] += count
        dec = None if extended else self.decoder.by_id.get(fid)
        if dec is None:
            return
        (self.good if dec.needed <= dlc <= dec.dlc else self.bad)[channel].add(fid)

    def add_messages(self, messages: Any, limit: int = PREFIX_FRAMES) -> None:
        for count, msg in enumerate(messages):
            if count >= limit:
                break
            ch = None if msg.channel is None else str(msg.channel)
            self.add(ch, msg.arbitration_id, len(msg.data), msg.is_extended_id)

    def verdict(self, channel: str | None) -> ChannelVerdict:
        good = self.good.get(channel, set())
        bad = self.bad.get(channel, set()) - good
        return ChannelVerdict(channel, len(good & self.periodic), len(self.periodic),
                              tuple(sorted(bad)))

    def camera(self) -> ChannelVerdict | None:
        """The channel that looks most like a camera when the protocol's IDs are on several
        channels; None when they are on one channel (or none): nothing to choose."""
        with_ids = [ch for ch in self.frames if self.good.get(ch) or self.bad.get(ch)]
        if len(with_ids) < 2:
            return self.verdict(with_ids[0]) if with_ids else None
        ranked = sorted((self.verdict(ch) for ch in with_ids),
                        key=lambda v: (v.periodic_seen, -len(v.wrong_dlc)), reverse=True)
        return ranked[0]

    def channels_with_ids(self) -> list[str]:
        return sorted(str(ch) for ch in self.frames if self.good.get(ch) or self.bad.get(ch))
