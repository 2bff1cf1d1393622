"""Segmentation of a message into transport payloads (seed 004 §6.1-6.2, decisions T1-T4).

Each returned payload is the data field of one link frame (at most 122 bytes; the link pads).
"""

from __future__ import annotations

from eyeq_spi.catalog.link import link_spec
from eyeq_spi.errors import LocalProtocolError

_T = link_spec()["transport"]
SINGLE: int = _T["types"]["single"]
FIRST: int = _T["types"]["first"]
CONSECUTIVE: int = _T["types"]["consecutive"]
SINGLE_MAX: int = _T["single_max"]
FIRST_CHUNK: int = _T["first_chunk"]
CONSECUTIVE_CHUNK: int = _T["consecutive_chunk"]
FIRST_TOTAL_MIN: int = _T["first_total_min"]
MAX_TOTAL: int = _T["max_total"]
ID_MODULO: int = _T["transfer_id_modulo"]


def segment(message: bytes, transfer_id: int) -> list[bytes]:
    """Split ``message`` (1..8191 bytes) into single or first+consecutive payloads."""
    total = len(message)
    if not 1 <= total <= MAX_TOTAL:
        raise LocalProtocolError(f"a message is 1..{MAX_TOTAL} bytes, got {total}")
    if total <= SINGLE_MAX:  # §6.1 / T2
        return [bytes((SINGLE, total)) + message]
    if not 0 <= transfer_id < ID_MODULO:
        raise LocalProtocolError(f"transfer ID {transfer_id} outside 0..{ID_MODULO - 1}")
    # §6.2.1 / T3: type, ID, total (uint32 LE), first 116 bytes
    out = [bytes((FIRST, transfer_id)) + total.to_bytes(4, "little") + message[:FIRST_CHUNK]]
    # §6.2.2 / T4: type, ID, next min(120, remaining) bytes
    for pos in range(FIRST_CHUNK, total, CONSECUTIVE_CHUNK):
        out.append(bytes((CONSECUTIVE, transfer_id)) + message[pos : pos + CONSECUTIVE_CHUNK])
    return out

