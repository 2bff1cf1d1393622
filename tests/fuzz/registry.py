"""Every in-process fuzz target by name, and the seeded coverage-free runner the CI slice uses
(random inputs, and mutations of earlier inputs)."""

from __future__ import annotations

import random

from .app_targets import decoders, host_eeprom, host_messages, init_codec, sim_messages
from .core import FIGURES, SliceResult, Target, mutate
from .link_targets import link_rx, transport_pair, transport_pair_wire

TARGETS: dict[str, Target] = {
    "link_rx": link_rx,
    "transport_pair": transport_pair,
    "transport_pair_wire": transport_pair_wire,
    "decoders": decoders,
    "init_codec": init_codec,
    "host_messages": host_messages,
    "sim_messages": sim_messages,
    "host_eeprom": host_eeprom,
}


def run_slice(name: str, inputs: int, seed: int, *, max_len: int = 512) -> SliceResult:
    """Feed ``inputs`` seeded inputs to target ``name``; collect what it finds (at most 5)."""
    target = TARGETS[name]
    rng = random.Random(f"{name}-{seed}")
    res = SliceResult()
    pool: list[bytes] = []
    for _ in range(inputs):
        if pool and rng.random() < 0.4:
            data = mutate(rng, rng.choice(pool))
        else:
            data = bytes(rng.randrange(256) for _ in range(rng.randrange(max_len)))
        if len(pool) < 64:
            pool.append(data)
        res.inputs += 1
        FIGURES["inputs"] += 1
        try:
            target(data)
        except Exception as exc:  # a Finding, a Hang, or a crash: all are results
            res.note(exc, data)
            if len(res.findings) >= 5:
                break
    return res
