"""``eyeq-spi bench doctor``: is a rig fit for a live EyeQ?

Frames go through every channel of a **loop** (one side's master wired to its own slave) or a
**pair** (two sides, each master to the other's slave); each is answered at once on the receiving
side's master channel, as the link answers DATA with an ACK. Every byte is checked and the reply
latency and round trip measured against the peer's
ackTimeout (seed 004 §6, 10 ms); docs/bench.md."""

from __future__ import annotations

import statistics
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.catalog.link import spec_file
from eyeq_spi.phy.spi import FRAME_LEN, REVERSED, SpiAdapter

ANSWER_WAIT = 0.5  # s to wait for a frame or reply before it counts as lost


def frame_pattern(index: int, reply: bool = False) -> bytes:
    """A 128-byte pattern unique to ``index`` (and to frame/reply) that exercises every bit:
    a walking one, its complement, the index, and a count."""
    head = bytes([0x5A if not reply else 0xA5, index & 0xFF, (index >> 8) & 0xFF, 0x00])
    walk = bytes(1 << (k % 8) for k in range(8)) + bytes(0xFF ^ (1 << (k % 8)) for k in range(8))
    body = bytes((index * 7 + k * 13 + (0x80 if reply else 0)) & 0xFF
                 for k in range(FRAME_LEN - 4 - len(walk)))
    return head + walk + body


def diagnose(sent: bytes, got: bytes | None) -> str:
    """``intact``, ``lost``, ``short``, ``bit_order`` (each byte reversed), ``mode`` (the bit
    stream shifted by one: sampled on the other clock edge) or ``corrupt``."""
    if got is None:
        return "lost"
    if got == sent:
        return "intact"
    if len(got) < len(sent):
        return "short"
    if got == sent.translate(REVERSED):
        return "bit_order"
    value = int.from_bytes(sent, "big")
    size = len(sent)
    if int.from_bytes(got, "big") in (value >> 1, (value << 1) & ((1 << 8 * size) - 1)):
        return "mode"
    return "corrupt"


def quantiles_ms(values: list[float]) -> dict[str, float | int]:
    """``n``, median, p99, p99.9 and max of latencies in seconds, in ms."""
    if not values:
        return {"n": 0}
    ordered = sorted(values)

    def rank(share: float) -> float:
        return ordered[min(len(ordered) - 1, int(share * len(ordered)))] * 1e3

    return {"n": len(ordered), "p50": round(statistics.median(ordered) * 1e3, 3),
            "p99": round(rank(0.99), 3), "p99_9": round(rank(0.999), 3),
            "max": round(ordered[-1] * 1e3, 3)}


@dataclass
class Tally:
    """What came through, by diagnosis, and the latencies read."""

    outcomes: Counter[str] = field(default_factory=Counter)
    reply: list[float] = field(default_factory=list)
    round_trip: list[float] = field(default_factory=list)


def _exchange(sender: SpiAdapter, receiver: SpiAdapter, index: int, tally: Tally) -> None:
    """One frame from ``sender``'s master to ``receiver``'s slave, answered at once by a reply
    from ``receiver``'s master to ``sender``'s slave."""
    frame, reply = frame_pattern(index), frame_pattern(index, reply=True)
    start = time.monotonic()
    sender.send(frame)
    got = receiver.recv(ANSWER_WAIT)
    outcome = diagnose(frame, got)
    tally.outcomes[outcome] += 1
    if got is None:
        return
    receiver.send(reply)  # at once, as the link's ACK
    tally.reply.append(receiver.wait_sent() - receiver.last_arrival)
    back = sender.recv(ANSWER_WAIT)
    if back is not None:
        tally.round_trip.append(sender.last_arrival - start)
    tally.outcomes[diagnose(reply, back)] += 1


def _drain(adapter: SpiAdapter) -> None:
    while adapter.recv(0.05) is not None:
        pass


def examine(side: SpiAdapter, peer: SpiAdapter | None = None, *,
            frames: int = 200) -> dict[str, Any]:
    """Send ``frames`` frames through every channel (loop: ``side`` to itself; pair: both
    ways between ``side`` and ``peer``), and judge the rig. Returns the report (see
    :func:`verdict_line` for its one line)."""
    tally = Tally()
    _drain(side)
    if peer is not None:
        _drain(peer)
    for index in range(frames):
        if peer is None:
            _exchange(side, side, index, tally)
        else:
            _exchange(side, peer, index, tally)
            _exchange(peer, side, index, tally)
    return judge(tally, wiring="loop" if peer is None else "pair",
                 adapters=[a.name for a in (side, peer) if a is not None])


def judge(tally: Tally, *, wiring: str, adapters: list[str]) -> dict[str, Any]:
    """The report and its verdict: fit when every frame and reply came through intact and
    the round trip's p99.9 is under ackTimeout (the reply latency is reported: it is the
    part of the round trip the PC adds)."""
    budget = float(spec_file("link.yaml")["timing"]["ackTimeout"])
    reply = quantiles_ms(tally.reply)
    trip = quantiles_ms(tally.round_trip)
    total = sum(tally.outcomes.values())
    bad = {k: v for k, v in tally.outcomes.items() if k != "intact"}
    reasons = []
    words = {"lost": "lost", "short": "short (chip select rose early)",
             "bit_order": "bit-reversed (the two ends disagree on the bit order)",
             "mode": "one bit off (the two ends disagree on the SPI mode, CPOL/CPHA)",
             "corrupt": "corrupted (wiring, ground or clock rate)"}
    for key, count in sorted(bad.items(), key=lambda kv: -kv[1]):
        reasons.append(f"{count} of {total} transfers {words[key]}")
    limit_ms = budget * 1e3
    if trip.get("p99_9", 0.0) >= limit_ms:
        reasons.append(f"round trip p99.9 {trip['p99_9']:.2f} ms is not under the "
                       f"{limit_ms:g} ms ackTimeout")
    if not tally.round_trip:
        reasons.append("no reply came back")
    return {"fit": not reasons, "reasons": reasons, "wiring": wiring, "adapters": adapters,
            "transfers": total, "outcomes": dict(sorted(tally.outcomes.items())),
            "reply_latency_ms": reply, "round_trip_ms": trip, "ack_timeout_ms": limit_ms}


def verdict_line(report: dict[str, Any]) -> str:
    """The doctor's one line."""
    if report["fit"]:
        trip, reply = report["round_trip_ms"], report["reply_latency_ms"]
        return (f"FIT for a live EyeQ: {report['transfers']} transfers intact "
                f"({report['wiring']}), reply p50 {reply['p50']:.2f} / p99 {reply['p99']:.2f}"
                f" / p99.9 {reply['p99_9']:.2f} ms, round trip p99.9 {trip['p99_9']:.2f} ms, "
                f"within the {report['ack_timeout_ms']:g} ms ackTimeout")
    return "NOT FIT for a live EyeQ: " + "; ".join(report["reasons"])
