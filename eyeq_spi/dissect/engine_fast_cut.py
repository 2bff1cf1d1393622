"""The lean modes of the fast path (``--stats`` or one table writer, no filter): a block's
messages cut a group at a time straight from the chunk's array, no bytes object per message.

:meth:`.engine_fast.ChunkFeeder._emit` gives the transfers (units) of the spans that complete in
a block. Here every unit whose frames are all in this chunk is located with numpy: its first row,
its message length (byte 7 of a single frame, T2; the total of a first frame, T3) and its first
four message bytes, which rule A (decision A) classifies. The units of one (direction, data ID)
DASP group, or one (direction, 0x41/0x10) group, that are all single frames or all first frames
with the same frame count become one ``(n, length)`` array in one gather:
:meth:`.engine_fast_messages.SpanDecoder.lean_group` judges it. Everything else — a group with a
transfer carried in from the previous chunk, mixed transfer shapes, a wrong length, MESP, unknown
IDs, a data ID in both directions when tables are written — becomes
:class:`~.engine_fast_messages.SpanMessage` objects and takes the non-lean
:meth:`~.engine_fast_messages.SpanDecoder.records`, as before.

The receivers' NUM -> capture index maps end as the engine's sequential updates leave them: one
bulk update per direction over the block's frames, in order (the last index of each NUM wins).
"""

from __future__ import annotations

import bisect
from typing import Any

import numpy as np

from eyeq_spi.capture.pcapng_fast import DIR_NAME
from eyeq_spi.codec.mesp import MESP_PROTOCOL
from eyeq_spi.codec.message import BOOT_ID, DASP_PROTOCOL, DIAG_ID, classify
from eyeq_spi.dissect.engine_fast_frames import FrameArrays
from eyeq_spi.dissect.engine_fast_messages import ColumnGroup, GroupCount, SpanMessage
from eyeq_spi.dissect.engine_fast_types import Dir, FeederState, Unit
from eyeq_spi.link.frame import SEQ_MODULO

DIAG_KEY, BOOT_KEY = 256, 257  # group keys of 0x41 / 0x10 messages beside DASP data IDs 0..255
_PROTO = {DIAG_KEY: "DIAG", BOOT_KEY: "BOOT"}
Done = list[tuple[int, Dir, Unit]]


def _key_of(data: bytes) -> int:
    """The group key of a reassembled message: its data ID (DASP), DIAG_KEY, BOOT_KEY, or -1."""
    proto = classify(data) if data else "UNKNOWN"
    if proto == "DASP" and len(data) >= 4:
        return data[1]
    return {"DIAG": DIAG_KEY, "BOOT": BOOT_KEY}.get(proto, -1)


Lean = tuple[list[tuple[int, dict[str, Any]]], list[ColumnGroup], list[GroupCount]]


def lean_messages(bd: FeederState, fa: FrameArrays, done: Done) -> Lean | None:
    """(row, record) of the messages that get a record, in row order; the column groups
    (``first``: their position among those records); the counts of the others. None: the
    block has a barrier message (:meth:`.engine_fast_messages.SpanDecoder.is_barrier`): the
    caller takes the non-lean path, which judges the messages on each side of it apart."""
    block = _Block(bd, fa, done)
    if not block.classify() or not block.take_carried():
        return None
    keys = set(zip(block.codes.tolist(), block.kind.tolist(), strict=True)) | set(block.loose_keys)
    dirs_of: dict[int, int] = {}
    for _, k in keys:
        dirs_of[k] = dirs_of.get(k, 0) + 1
    fallback: list[int] = []  # indices into done
    recs: list[tuple[int, dict[str, Any]]] = []
    tables: list[tuple[int, ColumnGroup]] = []
    counts: list[GroupCount] = []
    for code, k in sorted(keys):
        if k < 0:
            continue
        members, got = block.group(code, k, dirs_of[k])
        if got is None:
            fallback += members
            continue
        recs += got[0]
        if got[1] is not None:
            counts.append(got[1])
        if got[2] is not None:
            tables.append((got[2].first, got[2]))
    fb_recs, fb_tables = block.reference(fallback)
    recs += fb_recs
    tables += fb_tables
    recs.sort(key=lambda x: x[0])
    at = [r for r, _ in recs]
    out_tables = []
    for row, g in sorted(tables, key=lambda x: x[0]):
        g.first = bisect.bisect_left(at, row)
        out_tables.append(g)
    return recs, out_tables, counts


class _Block:
    """The units (transfers) that complete in one block, located in the chunk's array."""

    def __init__(self, bd: FeederState, fa: FrameArrays, done: Done) -> None:
        self.bd, self.fa, self.done = bd, fa, done
        self.dec = bd.decode
        self.loc: list[int] = []  # indices into done of the units wholly in this chunk
        self.carried: list[int] = []  # of a unit carried in from the previous chunk
        cols: list[tuple[int, int, int, int, bool]] = []
        for j, (row, st, u) in enumerate(done):
            if u.ks >= 0:
                self.loc.append(j)
                cols.append((row, st.code, u.ks, u.ke, u.first))
            else:
                self.carried.append(j)
        table = np.array(cols, np.int64).reshape(len(self.loc), 5)
        self.rows, self.codes, self.ks, self.ke = (table[:, i] for i in range(4))
        self.first = table[:, 4].astype(bool)
        self.P_np: dict[int, np.ndarray] = {}
        self.start = np.zeros(len(self.loc), np.int64)
        for code in sorted(set(self.codes.tolist())):  # not np.unique: imports numpy.ma (13 ms)
            self.P_np[code] = np.asarray(bd.rows[code], np.int64)
            sel = self.codes == code
            self.start[sel] = self.P_np[code][self.ks[sel]]
        self.loose: dict[int, SpanMessage] = {}
        self.loose_keys: dict[tuple[int, int], int] = {}  # one per direction: its first unit

    def classify(self) -> bool:
        """Each local unit's message length and group key (rule A); False: a barrier."""
        data, start, first = self.fa.chunk.data, self.start, self.first
        # T2 / T3: a single frame's size is byte 7, a first frame's total bytes 8..11
        total = np.ascontiguousarray(data[start, 8:12]).view("<u4")[:, 0].astype(np.int64)
        length = np.where(first, total, data[start, 7].astype(np.int64))
        col = np.where(first, 12, 8)
        b = data[start[:, None], col[:, None] + np.arange(5)].astype(np.int64)
        # rule A (codec.message.classify), in its order
        mesp = (length >= 3) & (b[:, 1] == MESP_PROTOCOL) & (b[:, 0] == b[:, 2])
        kind = np.full(len(length), -1, np.int64)
        other = ~mesp & (length >= 1)
        dasp = other & (b[:, 0] == DASP_PROTOCOL) & (length >= 4)
        kind[dasp] = b[dasp, 1]
        kind[other & (b[:, 0] == DIAG_ID)] = DIAG_KEY
        kind[other & (b[:, 0] == BOOT_ID)] = BOOT_KEY
        self.length, self.kind = length, kind
        # a MESP request of a barrier function (its service and function, reply bit clear)
        req = mesp & (length >= 5) & ((b[:, 4] & 0x80) == 0)
        return not (req.any() and any(self.dec.is_barrier(bytes(x))
                                      for x in b[req].astype(np.uint8).tolist()))

    def take_carried(self) -> bool:
        """The carried transfers (frames from the previous chunk) as span messages; False: a
        barrier among them."""
        for j in self.carried:
            row, st, u = self.done[j]
            msg = self.bd.message(self.fa, st, u, row)
            if self.dec.is_barrier(msg.data):
                return False
            self.loose[j] = msg
            self.loose_keys[(st.code, _key_of(msg.data))] = j
        return True

    def group(self, code: int, key: int, directions: int
              ) -> tuple[list[int], tuple[Any, Any, Any] | None]:
        """One (direction, key) group's members (indices into done) and what
        :meth:`~.engine_fast_messages.SpanDecoder.lean_group` made of them (None: the
        reference judges them)."""
        ix = np.flatnonzero((self.codes == code) & (self.kind == key))
        jc = self.loose_keys.get((code, key))  # a carried transfer: the group's first message
        members = ([] if jc is None else [jc]) + [self.loc[i] for i in ix.tolist()]
        columns_mode = self.dec.fields == "columns"
        if columns_mode and directions > 1:
            return members, None
        arr = (_gather(self.fa.chunk.data, self.P_np.get(code), self.first[ix], self.ks[ix],
                       self.ke[ix], self.start[ix], self.length[ix])
               if ix.size else np.zeros((0, 0), np.uint8))
        if arr is not None and jc is not None:
            head = np.frombuffer(self.loose[jc].data, np.uint8)
            arr = (head[None, :] if not ix.size else
                   np.concatenate([head[None, :], arr]) if len(head) == arr.shape[1] else None)
        if arr is None:
            return members, None
        base = self.fa.base
        grows = self.rows[ix] if jc is None else np.concatenate([[self.done[jc][0]],
                                                                 self.rows[ix]])
        gks = [0] * (jc is not None) + self.ks[ix].tolist()
        gke = [0] * (jc is not None) + self.ke[ix].tolist()
        P = self.bd.rows[code]
        carried_frames = None if jc is None else self.loose[jc].frames
        last = (base + grows).tolist()
        if carried_frames is not None:
            last[0] = carried_frames[-1] if carried_frames else None

        def frames_of(i: int) -> list[int | None]:
            if i == 0 and carried_frames is not None:
                return list(carried_frames)
            return [base + r for r in P[gks[i] : gke[i]]]

        st = self.done[members[0]][1]
        return members, self.dec.lean_group(st.name, _PROTO.get(key, key), arr, grows.tolist(),
                                            self.fa.tfill[grows], last, frames_of,
                                            columns_mode and directions == 1)

    def reference(self, fallback: list[int]
                  ) -> tuple[list[tuple[int, dict[str, Any]]], list[tuple[int, ColumnGroup]]]:
        """The records (and column groups) of the units no lean group took, and of those
        without a group key, in row order; the receivers' NUM maps brought up to date."""
        done = self.done
        exact = [self.loc[i] for i in np.flatnonzero(self.kind < 0).tolist()]
        exact += [j for key, j in self.loose_keys.items() if key[1] < 0]
        order = sorted(fallback + exact, key=lambda j: done[j][0])
        msgs = [self.loose[j] if j in self.loose
                else self.bd.message(self.fa, done[j][1], done[j][2], done[j][0])
                for j in order]
        _bulk_maps(self.bd, self.fa, self.codes, self.ks, self.ke, self.P_np)
        rows = [done[j][0] for j in order]
        recs = list(zip(rows, self.dec.records(msgs), strict=True))
        return recs, [(rows[g.first], g) for g in self.dec.tables]


def _gather(data: np.ndarray, P: np.ndarray | None, first: np.ndarray, ks: np.ndarray,
            ke: np.ndarray, start: np.ndarray, length: np.ndarray) -> np.ndarray | None:
    """The messages of a group as one ``(n, length)`` array, or None (not one shape)."""
    size = int(length[0])
    if P is None or (length != size).any():
        return None
    if not first.any():
        if 8 + size > data.shape[1]:
            return None
        return data[start, 8 : 8 + size]
    if not first.all():
        return None
    nf = ke - ks
    f = int(nf[0])
    if (nf != f).any():
        return None
    blk = data[P[ks[:, None] + np.arange(f)]]  # (n, frames, 128)
    n = len(ks)
    out = np.concatenate([blk[:, 0, 12:], blk[:, 1:, 8:].reshape(n, -1)], axis=1)
    if out.shape[1] < size:
        return None
    return out[:, :size]


def _bulk_maps(bd: FeederState, fa: FrameArrays, codes: np.ndarray, ks: np.ndarray,
               ke: np.ndarray, P_np: dict[int, np.ndarray]) -> None:
    """Every frame of the block's local units into its receiver's NUM -> index map, in order
    (a direction's units are consecutive in its rows, so their frames are one range)."""
    for code, P in P_np.items():
        sel = codes == code
        rr = P[int(ks[sel].min()) : int(ke[sel].max())]
        nums = fa.num[rr]
        if len(rr) > SEQ_MODULO:  # only each NUM's last frame stays in the map
            last, at = np.unique(nums[::-1], return_index=True)
            rr, nums = rr[len(rr) - 1 - at], last
        bd.dis.note_frames(DIR_NAME[code], nums.tolist(), (fa.base + rr).tolist())
