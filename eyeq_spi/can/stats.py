"""``can decode --stats``: frames per channel and ID, cycle time against the spec, DLC errors,
short DLCs (decision C8), invalid and out-of-range values per signal.

Frames are only collected per (channel, ID) while the log is read (timestamp and payload); each
ID is decoded in chunks with numpy, signal by signal, with the same compiled
:class:`~eyeq_spi.can.decode.MessageDecoder` as the per-frame decoder. Decision C9: cycle times
that differ from the seed's are shown as deviations, never counted as errors.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.can.channels import ChannelCensus
from eyeq_spi.can.decode import CanDecoder, MessageDecoder, pack

CHUNK = 1 << 15  # frames per (channel, ID) decoded at once: memory stays bounded


@dataclass
class _Key:
    name: str | None
    frames: int = 0
    error_frames: int = 0
    dlc_errors: int = 0
    short_dlc: int = 0
    last: float | None = None
    intervals: list[Any] = field(default_factory=list)  # numpy arrays (ms)
    n_intervals: int = 0
    invalid: Counter[str] = field(default_factory=Counter)
    out_of_range: Counter[str] = field(default_factory=Counter)
    sizes: set[int] = field(default_factory=set)  # DLCs seen
    quality: list[tuple[Any, Any]] = field(default_factory=list)  # (times, quality) (C11)


class CanStats:
    """Streaming statistics of one protocol; ``channel`` keeps only that channel's frames."""

    MAX_INTERVALS = 100_000  # per ID

    def __init__(self, decoder: CanDecoder, channel: str | None = None,
                 file: str | None = None) -> None:
        self.decoder = decoder
        self.channel = channel
        self.file = file
        # (times, payloads, times.append, payloads.append) per (channel, ID, extended)
        self._buf: dict[tuple[Any, int, bool], tuple[list[float], list[bytes], Any, Any]] = {}
        self._keys: dict[tuple[str | None, int], _Key] = {}
        self.per_channel: Counter[str | None] = Counter()
        self.unknown: Counter[tuple[str | None, int]] = Counter()  # other traffic (C10)
        self.first: float | None = None
        self.last: float | None = None

    def add_all(self, messages: Any) -> None:
        """python-can messages (the hot path: one append per frame)."""
        buffers = self._buf
        get = buffers.get
        for msg in messages:
            key = (msg.channel, msg.arbitration_id, msg.is_extended_id)
            buf = get(key)
            if buf is None:
                times: list[float] = []
                datas: list[bytes] = []
                buf = buffers[key] = (times, datas, times.append, datas.append)
            buf[2](msg.timestamp)
            buf[3](msg.data)
            if len(buf[0]) >= CHUNK:
                self._flush(key)

    def _flush(self, key: tuple[Any, int, bool]) -> None:
        import numpy as np

        times, datas, _, _ = self._buf.pop(key)
        ch_raw, fid, ext = key
        ch = None if ch_raw is None else str(ch_raw)
        count = len(times)
        self.per_channel[ch] += count
        if self.channel is not None and ch != self.channel:
            return
        stamps = np.asarray(times, dtype=np.float64)
        lo, hi = float(np.min(stamps)), float(np.max(stamps))
        self.first = lo if self.first is None else min(self.first, lo)
        self.last = hi if self.last is None else max(self.last, hi)
        dec = None if ext else self.decoder.by_id.get(fid)
        if dec is None:
            self.unknown[(ch, fid)] += count
            return
        st = self._keys.setdefault((ch, fid), _Key(dec.name))
        st.frames += count
        if st.n_intervals < self.MAX_INTERVALS:
            prev = stamps if st.last is None else np.concatenate(([st.last], stamps))
            iv = np.diff(prev) * 1000.0
            st.intervals.append(iv)
            st.n_intervals += len(iv)
        st.last = float(stamps[-1])
        source = dec.quality_source
        if source is not None and source != fid and (ch_raw, source, False) in self._buf:
            self._flush((ch_raw, source, False))  # its qualities up to now come first (C11)
        self._decode(dec, datas, st, stamps, ch)

    def _low_quality(self, dec: MessageDecoder, ch: str | None, stamps: Any, le: Any, be: Any,
                     pad: int, st: _Key) -> Any:
        """Decision C11: which frames' governed signals are invalid (their lane's quality, in
        this frame or the latest frame of the message that carries it, is low); None if no
        rule."""
        import numpy as np

        rule = dec.quality
        if rule is None:
            return None
        if dec.quality_source == dec.spec.id or dec.quality_source is None or \
                self.decoder.by_id[dec.quality_source] is dec:
            quality_sig = next(s for s in dec.signals if s.spec.name == rule.signal)
            word = be if quality_sig.big_endian else le
            shift = quality_sig.shift + pad if quality_sig.big_endian else quality_sig.shift
            quality = ((word >> np.uint64(shift)) & np.uint64(quality_sig.mask)).astype(np.int64)
            st.quality.append((stamps, quality))
            return quality < rule.valid_from
        src = self._keys.get((ch, dec.quality_source))
        if src is None or not src.quality:
            return np.zeros(len(stamps), dtype=bool)
        times = np.concatenate([x[0] for x in src.quality])
        values = np.concatenate([x[1] for x in src.quality])
        at = np.searchsorted(times, stamps, side="right") - 1
        return (at >= 0) & (values[np.maximum(at, 0)] < rule.valid_from)

    def _decode(self, dec: MessageDecoder, datas: list[bytes], st: _Key, stamps: Any,
                ch: str | None) -> None:
        import numpy as np

        count = len(datas)
        sizes = set(map(len, datas))
        st.sizes |= sizes
        if len(sizes) == 1:  # the usual case: one length per ID (8, or the camera's short 4)
            size = sizes.pop()
            lens = np.full(count, size, dtype=np.int64)
            arr = np.frombuffer(b"".join(datas), dtype=np.uint8).reshape(count, size)[:, :dec.dlc]
            if size < dec.dlc:
                arr = np.pad(arr, ((0, 0), (0, dec.dlc - size)))
        else:
            lens = np.fromiter(map(len, datas), dtype=np.int64, count=count)
            arr = np.frombuffer(b"".join(bytes(d[:dec.dlc]).ljust(dec.dlc, b"\0") for d in datas),
                                dtype=np.uint8).reshape(count, dec.dlc)
        short = (lens < dec.dlc) & (lens >= dec.needed)
        bad_dlc = (lens != dec.dlc) & ~short
        have = np.where(bad_dlc, np.minimum(lens, dec.dlc), dec.dlc)
        st.short_dlc += int(short.sum())
        st.dlc_errors += int(bad_dlc.sum())
        full = np.zeros((count, 8), dtype=np.uint8)
        full[:, :dec.dlc] = arr
        le = full.view("<u8").ravel()
        be = full.view(">u8").ravel().astype(np.uint64)
        pad = (8 - dec.dlc) * 8
        err = bad_dlc.copy()
        low = self._low_quality(dec, ch, stamps, le, be, pad, st)
        with np.errstate(invalid="ignore", over="ignore"):  # NaN floats: not finite, skipped
            for sig in dec.signals:
                self._signal(sig, le, be, pad, have, st, err,
                             low if sig.spec.name in dec.governed else None)
        st.error_frames += int(err.sum())

    @staticmethod
    def _signal(sig: Any, le: Any, be: Any, pad: int, have: Any, st: _Key, err: Any,
                low: Any) -> None:
        import numpy as np

        count = len(le)
        present = have >= sig.nbytes
        word = be if sig.big_endian else le
        shift = sig.shift + pad if sig.big_endian else sig.shift
        raw_u = (word >> np.uint64(shift)) & np.uint64(sig.mask)
        phys: Any
        if sig.spec.is_float:
            phys = raw_u.astype(np.uint32).view(np.float32).astype(np.float64)
            raw = raw_u.astype(np.int64)
        else:
            raw = raw_u.astype(np.int64)
            if sig.sign_bit:
                raw = np.where(raw & sig.sign_bit, raw - (sig.mask + 1), raw)
            phys = raw * float(sig.scale) + float(sig.offset)
        inv = present & (raw == sig.invalid) if sig.invalid is not None else \
            np.zeros(count, dtype=bool)
        if low is not None:
            inv |= present & low
        invalid = int(inv.sum())
        if invalid:
            st.invalid[sig.spec.name] += invalid
        oor = np.zeros(count, dtype=bool)
        if sig.low is not None:
            oor |= phys < sig.low
        if sig.high is not None:
            oor |= phys > sig.high
        oor &= present & ~inv & np.isfinite(phys)
        out_of_range = int(oor.sum())
        if out_of_range:
            st.out_of_range[sig.spec.name] += out_of_range
            err |= oor

    def finish(self) -> None:
        for key in list(self._buf):
            if key in self._buf:  # a lane's A frames go before its B frames (C11)
                self._flush(key)

    @property
    def frames(self) -> int:
        return sum(s.frames for s in self._keys.values()) + sum(self.unknown.values())

    def census(self) -> ChannelCensus:
        """Which protocol IDs each channel carries, and at which DLCs (C10)."""
        out = ChannelCensus(self.decoder)
        for (ch, fid), st in self._keys.items():
            for size in st.sizes:
                out.add(ch, fid, size, count=0)
            out.frames[ch] += st.frames
        for (ch, _), count in self.unknown.items():
            out.frames[ch] += count
        return out

    def result(self) -> dict[str, Any]:
        """The statistics of what was read: per ID of the camera's channel (the one given, or
        the one that looks most like a camera when the protocol's IDs are on several), and the
        other nodes' traffic apart (C10)."""
        self.finish()
        census = self.census()
        verdict = census.verdict(self.channel) if self.channel is not None else census.camera()
        several = len(census.channels_with_ids()) > 1
        camera = verdict.channel if verdict is not None and several else None
        per_id: list[dict[str, Any]] = []
        other: Counter[int] = Counter({fid: n for (_, fid), n in self.unknown.items()})
        id_channels: defaultdict[int, list[str | None]] = defaultdict(list)
        for (ch, fid), st in sorted(self._keys.items(), key=lambda kv: (kv[0][1], str(kv[0][0]))):
            id_channels[fid].append(ch)
            if camera is not None and ch != camera:
                other[fid] += st.frames
                continue
            per_id.append(self._id_row(ch, fid, st))
        shared = {f"0x{fid:X}": sorted(str(c) for c in chs)
                  for fid, chs in sorted(id_channels.items()) if len(chs) > 1}
        warning = None
        if verdict is not None and self.channel is not None and not verdict.looks_like_camera:
            warning = (f"channel {self.channel} does not look like a camera: "
                       f"{verdict.describe()} of {self.decoder.protocol.name}")
        return {"kind": "stats", "file": self.file, "protocol": self.decoder.protocol.name,
                "frames": self.frames, "channel": self.channel,
                "channels": {str(k): v for k, v in sorted(self.per_channel.items(),
                                                          key=lambda kv: str(kv[0]))},
                "camera_channel": None if verdict is None else verdict.channel,
                "camera_evidence": None if verdict is None else verdict.describe(),
                "warning": warning,
                "ids_on_several_channels": shared,
                "duration_s": None if self.first is None or self.last is None
                else round(self.last - self.first, 6),
                "other_frames": sum(other.values()),
                "other_ids": {f"0x{k:X}": v for k, v in sorted(other.items())},
                "error_frames": sum(r["error_frames"] for r in per_id),
                "dlc_errors": sum(r["dlc_errors"] for r in per_id),
                "short_dlc": sum(r["short_dlc"] for r in per_id),
                "invalid_values": sum(sum(r["invalid"].values()) for r in per_id),
                "out_of_range_values": sum(sum(r["out_of_range"].values()) for r in per_id),
                "ids": per_id}

    def _id_row(self, ch: str | None, fid: int, st: _Key) -> dict[str, Any]:
        import numpy as np

        spec = self.decoder.spec_for(fid)
        cyc = spec.cycle_ms if spec else None
        iv = np.concatenate(st.intervals)[:self.MAX_INTERVALS] if st.intervals else None
        med = float(np.median(iv)) if iv is not None and len(iv) else None
        mean = float(np.mean(iv)) if iv is not None and len(iv) else None
        return {
            "id": fid, "channel": ch, "name": st.name, "frames": st.frames,
            "spec_cycle_ms": cyc,
            "median_cycle_ms": None if med is None else round(med, 3),
            "mean_cycle_ms": None if mean is None else round(mean, 3),
            "cycle_deviation_pct": None if med is None or not cyc
            else round(100.0 * (med - cyc) / cyc, 2),
            "invalid": dict(st.invalid), "out_of_range": dict(st.out_of_range),
            "dlc_errors": st.dlc_errors, "short_dlc": st.short_dlc,
            "error_frames": st.error_frames,
        }


TOTAL_KEYS = ("frames", "other_frames", "error_frames", "dlc_errors", "short_dlc",
              "invalid_values", "out_of_range_values")


def total(results: list[dict[str, Any]]) -> dict[str, Any]:
    """The counts of several files' statistics added up (``"file": null``, ``"files": N``); per
    ID its frames and errors only: a cycle time never spans two files."""
    ids: dict[tuple[int, str | None], dict[str, Any]] = {}
    for result in results:
        for row in result["ids"]:
            entry = ids.setdefault((row["id"], row["channel"]), {
                "id": row["id"], "channel": row["channel"], "name": row["name"], "frames": 0,
                "error_frames": 0})
            entry["frames"] += row["frames"]
            entry["error_frames"] += row["error_frames"]
    other: Counter[str] = Counter()
    for result in results:
        other.update(result["other_ids"])
    return {"kind": "stats", "file": None, "files": len(results),
            "protocol": results[0]["protocol"] if results else None,
            **{k: sum(result[k] for result in results) for k in TOTAL_KEYS},
            "other_ids": dict(sorted(other.items())),
            "ids": [ids[k] for k in sorted(ids, key=lambda k: (k[0], str(k[1])))]}


def human_total(stats: dict[str, Any]) -> str:
    return "\n".join([
        f"=== total of {stats['files']} files",
        f"{stats['frames']} frames, protocol {stats['protocol']}; other nodes' traffic "
        f"{stats['other_frames']} frames",
        _errors_line(stats)])


def _errors_line(stats: dict[str, Any]) -> str:
    return pack(f"errors: {stats['error_frames']} frames", [
        f"(DLC errors {stats['dlc_errors']},",
        f"values out of range {stats['out_of_range_values']});",
        f"short DLCs {stats['short_dlc']} (accepted);",
        f"invalid values {stats['invalid_values']} (as sent: not errors)"], indent=4)


def human_stats(stats: dict[str, Any], heading: bool = False) -> str:
    """One file's statistics, to 80 columns; ``heading``: ``=== FILE`` first."""
    chans = ", ".join(f"{k}: {v}" for k, v in stats["channels"].items())
    span = "-" if stats["duration_s"] is None else f"{stats['duration_s']:.3f}"
    lines = [f"=== {stats['file']}"] if heading else []
    lines += [f"{stats['frames']} frames over {span} s, protocol {stats['protocol']}"
              + (f", channel {stats['channel']}" if stats["channel"] is not None else ""),
              f"channels (all frames in the log): {chans or 'none'}"]
    if stats["camera_channel"] is not None and stats["channel"] is None:
        camera = stats["camera_channel"]
        lines.append(pack(f"camera on channel {camera}:",
                          f"{stats['camera_evidence']} (--channel {camera})".split(), indent=4))
    if stats["ids_on_several_channels"] and stats["channel"] is None:
        ids = "; ".join(f"{k} on {', '.join(v)}"
                        for k, v in stats["ids_on_several_channels"].items())
        lines.append(pack("note: protocol IDs on several channels", [
            *f"({ids}):".split(" "), "those", "off", "the", "camera's", "channel", "are",
            "other", "traffic"], indent=6))
    other = [f"{k} x{v}," for k, v in stats["other_ids"].items()]
    if other:
        other[-1] = other[-1].rstrip(",") + ")"
        lines.append(pack(f"other nodes' traffic: {stats['other_frames']} frames (IDs",
                          other, indent=4))
    lines.append(_errors_line(stats))
    rows = stats["ids"]
    several = any(entry["channel"] != rows[0]["channel"] for entry in rows) if rows else False
    lines.append(f"{'ID':>6s} {'ch':>3s} {'message':26s} {'frames':>7s} {'cycle ms':>9s} "
                 f"{'spec':>5s} {'dev %':>7s}"
                 if several else
                 f"{'ID':>6s} {'message':26s} {'frames':>7s} {'cycle ms':>9s} {'spec':>5s} "
                 f"{'dev %':>7s}")
    for entry in stats["ids"]:
        med = "-" if entry["median_cycle_ms"] is None else f"{entry['median_cycle_ms']:.1f}"
        deviation = entry["cycle_deviation_pct"]
        dev = ("-" if deviation is None
               else "0.0" if abs(deviation) < 0.05 else f"{deviation:+.1f}")
        probs = ([f"DLC errors x{entry['dlc_errors']}"] if entry["dlc_errors"] else []) \
            + ([f"short DLC x{entry['short_dlc']}"] if entry["short_dlc"] else []) \
            + [f"{k} invalid x{v}" for k, v in entry["invalid"].items()] \
            + [f"{k} out of range x{v}" for k, v in entry["out_of_range"].items()]
        ch = f" {entry['channel'] or '-':>3s}" if several else ""
        spec = "-" if entry["spec_cycle_ms"] is None else f"{entry['spec_cycle_ms']:g}"
        row = (f"0x{entry['id']:04X}{ch} {entry['name']:26s} {entry['frames']:7d} {med:>9s} "
               f"{spec:>5s} {dev:>7s}")
        # the findings of a row fold under it, between findings, to 80 columns
        lines.append(pack(row, [p + "," for p in probs[:-1]] + probs[-1:], indent=8)
                     if probs else row)
    return "\n".join(lines)
