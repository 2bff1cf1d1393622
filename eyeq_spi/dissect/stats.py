"""``eyeq-spi dissect --stats``: what a capture contains and what went wrong in it.

One :class:`Stats` per file; :func:`combine` adds several up into a total whose mean rates are
each file's message intervals over each file's active spans (eyeq_spi/stream_rate.py), so a
rate never spans two files, nor a gap in a stream.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.catalog.messages import Catalog
from eyeq_spi.stream_rate import stream_rate

MESP_DEADLINE = 0.5  # M6


@dataclass
class Stats:
    """``dissect --stats``: counts, rates, errors and MESP latencies of one capture (or, from
    :func:`combine`, the total of several)."""

    cat: Catalog
    frames: Counter[str] = field(default_factory=Counter)
    bad_length: int = 0
    crc_errors: int = 0
    nak_reasons: Counter[str] = field(default_factory=Counter)
    aborts: Counter[str] = field(default_factory=Counter)
    events: Counter[str] = field(default_factory=Counter)
    messages: Counter[str] = field(default_factory=Counter)
    times: dict[str, list[float]] = field(default_factory=dict)  # of each stream's messages
    counter_gaps: Counter[str] = field(default_factory=Counter)
    e2e_errors: Counter[str] = field(default_factory=Counter)
    message_errors: int = 0
    mesp_pending: dict[tuple[Any, ...], tuple[float, str]] = field(default_factory=dict)
    mesp_latency: dict[str, list[float]] = field(default_factory=dict)
    mesp_timeouts: Counter[str] = field(default_factory=Counter)
    mesp_unmatched: int = 0
    file: str | None = None  # the capture these statistics describe (None: a total)
    sw: dict[str, Any] = field(default_factory=dict)  # {"sw": "8.1", "sw_source": ...}
    ignored_bytes: int = 0  # bytes of an incomplete last block the reader left
    files: int = 0  # a total: how many files it adds up (0: one file's own statistics)
    spans: dict[str, float] = field(default_factory=dict)  # a total: sum of per-file spans
    steps: Counter[str] = field(default_factory=Counter)  # a total: sum of per-file intervals

    def add(self, record: dict[str, Any]) -> None:
        kind = record["kind"]
        if kind == "frame":
            ft = record["frame_type"]
            self.frames[ft] += 1
            if "length" in record:
                self.bad_length += 1
            elif not record["crc_ok"]:
                self.crc_errors += 1
            if ft == "NAK" and record["crc_ok"]:
                self.nak_reasons[f"0x{record['nak_reason']:03X}"] += 1
        elif kind == "event":
            self.events[record["type"]] += 1
            if record["type"] == "transfer_aborted":
                self.aborts[record["reason"]] += 1
        elif kind == "message":
            self._message(record)

    def _message(self, record: dict[str, Any]) -> None:
        name = record["name"] or record["protocol"]
        self.messages[name] += 1
        time_s = record.get("time")
        if time_s is not None:
            self.times.setdefault(name, []).append(time_s)
        for error in record["errors"]:
            if error.startswith("DASP counter gap"):
                self.counter_gaps[name] += 1
            elif error.startswith("E2E"):
                self.e2e_errors[name] += 1
            else:
                self.message_errors += 1
        if record["protocol"] == "MESP" and record["header"] and time_s is not None:
            header = record["header"]
            key = (header["service"], header["function"], header["counter"])
            if not header["reply"]:
                self._expire(time_s)
                self.mesp_pending[key] = (time_s, name)
            else:
                sent = self.mesp_pending.pop(key, None)
                if sent is None:
                    self.mesp_unmatched += 1
                elif time_s - sent[0] > MESP_DEADLINE:
                    self.mesp_timeouts[name] += 1
                else:
                    self.mesp_latency.setdefault(name, []).append(time_s - sent[0])

    def _expire(self, now: float) -> None:
        for key, (sent_at, name) in list(self.mesp_pending.items()):
            if now - sent_at > MESP_DEADLINE:
                del self.mesp_pending[key]
                self.mesp_timeouts[name] += 1

    def finish(self) -> None:
        self._expire(float("inf"))

    @property
    def protocol_errors(self) -> int:
        return (self.crc_errors + self.bad_length + sum(self.nak_reasons.values())
                + self.frames.get("INVALID", 0) + sum(self.aborts.values())
                + sum(self.counter_gaps.values()) + sum(self.e2e_errors.values())
                + self.message_errors + self.events.get("frame_rejected", 0))

    def as_dict(self) -> dict[str, Any]:
        rates: dict[str, Any] = {}
        for name, count in sorted(self.messages.items()):
            gaps = 0
            if self.files:
                span, steps = self.spans.get(name, 0.0), self.steps.get(name, 0)
            else:  # over the stream's active spans (eyeq_spi/stream_rate.py)
                rate = stream_rate(sorted(self.times.get(name, [])))
                span, steps, gaps = rate.active_s, rate.steps, len(rate.gaps)
            try:
                nominal = self.cat.message(name).rate_hz
            except Exception:  # MESP, a protocol name: no nominal rate
                nominal = None
            periodic = nominal is not None and span > 0 and steps > 0
            rates[name] = {"count": count, "mean_hz": round(steps / span, 3) if periodic else None,
                           "nominal_hz": nominal, "gaps": gaps if periodic else 0}
        from statistics import median  # here: start-up of runs without MESP replies

        lat = {
            name: {"count": len(v), "min_ms": round(min(v) * 1e3, 3),
                   "median_ms": round(median(v) * 1e3, 3),
                   "max_ms": round(max(v) * 1e3, 3), "timeouts": self.mesp_timeouts.get(name, 0)}
            for name, v in sorted(self.mesp_latency.items())
        }
        for name, count in self.mesp_timeouts.items():
            lat.setdefault(name, {"count": 0, "timeouts": count})
        head: dict[str, Any] = {"kind": "stats", "file": self.file}
        if self.files:
            head["files"] = self.files
        head.update(self.sw)
        return {
            **head, "ignored_bytes": self.ignored_bytes,
            "frames": dict(self.frames), "bad_length": self.bad_length,
            "crc_errors": self.crc_errors, "nak_reasons": dict(self.nak_reasons),
            "aborted_transfers": dict(self.aborts), "events": dict(self.events),
            "messages": rates, "dasp_counter_gaps": dict(self.counter_gaps),
            "e2e_errors": dict(self.e2e_errors), "message_errors": self.message_errors,
            "mesp_latency": lat, "mesp_unmatched_replies": self.mesp_unmatched,
            "protocol_errors": self.protocol_errors,
        }

    def render(self) -> str:
        view = self.as_dict()
        out = []
        if self.files:
            out.append(f"=== total of {self.files} files")
        elif self.file is not None:
            src = f" (SW {view['sw']}: {view['sw_source']})" if "sw" in view else ""
            if "clock" in view:  # what the timestamps were read from (docs/captures.md)
                src += f", clock: {view['clock'] or 'not recorded'}"
            out.append(f"=== {self.file}{src}")
        if self.ignored_bytes:
            out.append(f"  ignored {self.ignored_bytes} bytes of an incomplete last block")
        frames = "  ".join(f"{k} {v}" for k, v in sorted(view["frames"].items()))
        out += ["== frames", "  " + frames,
               f"  CRC errors {view['crc_errors']}, wrong length {view['bad_length']}, NAK reasons "
               f"{view['nak_reasons'] or 'none'}, "
               f"aborted transfers {view['aborted_transfers'] or 'none'}",
               # L9: cut by the capture's start or end, not a protocol error
               f"  incomplete transfers: at start {view['events'].get('incomplete_at_start', 0)}, "
               f"at end {view['events'].get('incomplete_at_end', 0)}",
               "== messages (count, mean rate / nominal)"]
        for name, row in view["messages"].items():
            mean = "-" if row["mean_hz"] is None else f"{row['mean_hz']:.2f} Hz"
            nom = "" if row["nominal_hz"] is None else f" / {row['nominal_hz']:g} Hz"
            gaps = row.get("gaps") or 0
            out.append(f"  {name:34s} {row['count']:8d}  {mean}{nom}"
                       + (f"  ({gaps} gap{'s' if gaps > 1 else ''})" if gaps else ""))
        out.append(f"== DASP counter gaps {view['dasp_counter_gaps'] or 'none'}; "
                   f"E2E errors {view['e2e_errors'] or 'none'}; other message errors "
                   f"{view['message_errors']}")
        out.append("== MESP request -> reply latency, ms (min / median / max)")
        for name, row in view["mesp_latency"].items():
            if row.get("count"):  # 80 columns wide
                out.append(f"  {name:30s} n={row['count']:<5d} {row['min_ms']:.3f} / "
                           f"{row['median_ms']:.3f} / {row['max_ms']:.3f}  "
                           f"timeouts {row['timeouts']}")
            else:
                out.append(f"  {name:30s} timeouts {row['timeouts']}")
        out.append(f"== protocol errors: {view['protocol_errors']}")
        return "\n".join(out)


def combine(parts: list[Stats]) -> Stats:
    """The total of several files' finished statistics."""
    total = Stats(parts[0].cat, files=len(parts))
    for part in parts:
        for name in ("frames", "nak_reasons", "aborts", "events", "messages", "counter_gaps",
                     "e2e_errors", "mesp_timeouts"):
            getattr(total, name).update(getattr(part, name))
        for name in ("bad_length", "crc_errors", "message_errors", "mesp_unmatched",
                     "ignored_bytes"):
            setattr(total, name, getattr(total, name) + getattr(part, name))
        for name, times in part.times.items():
            rate = stream_rate(sorted(times))  # each file's active spans, never across two
            total.spans[name] = total.spans.get(name, 0.0) + rate.active_s
            total.steps[name] += rate.steps
        for name, latencies in part.mesp_latency.items():
            total.mesp_latency.setdefault(name, []).extend(latencies)
    return total

