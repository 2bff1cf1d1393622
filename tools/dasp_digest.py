"""A digest of what the simulated EyeQ sends: per SW release and DASP path, the SHA-256 of every
DASP message of a full-load run in Running Vision (the link stubbed, the ego speed and yaw rate
changing), so that a change meant to make the simulator faster can show it sends the same bytes.

    python tools/dasp_digest.py [--seconds S] [--before REV]

``--before REV`` computes the digests of ``git archive REV`` of this repository too and prints
the releases whose bytes differ (exit 1 if any does).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
# this checkout's eyeq_spi (not an installed copy), or with --before the revision's tree
sys.path.insert(0, os.environ.get("EYEQ_SPI_DIGEST_TREE", str(ROOT)))


def digests(seconds: float) -> list[str]:
    """``release seed path digest`` lines, one per release and path (dict, packer)."""
    from eyeq_spi.catalog.messages import catalog
    from eyeq_spi.sim.config import SimConfig
    from eyeq_spi.sim.eyeq import Phase, SimulatedEyeQ

    out: list[str] = []
    for sw in catalog().sw_versions:
        for seed, packer in ((3, True), (4, False)):
            sim = SimulatedEyeQ(SimConfig(sw=sw, seed=seed, objects=15, signs=20,
                                          light_spots=15, dasp_packer=packer))
            sim.warm_up()
            h = hashlib.sha256()
            sim.phase, sim.main_state = Phase.RUNNING, 0x02  # Running Vision

            def send(message: bytes, now: float, h: Any = h) -> None:
                h.update(message)

            sim._send = send  # type: ignore[method-assign]
            sim._send_due_dasp(0.0)
            while sim._dasp_min < seconds:
                sim._ego = (20.0 + sim._dasp_min, 0.01)  # as the host's HOST_VEH_STATE_MSG sets it
                sim._send_due_dasp(sim._dasp_min)
            out.append(f"{sw} {seed} {'packer' if packer else 'dict'} {h.hexdigest()}")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=12.0)
    ap.add_argument("--before", metavar="REV", help="compare with this git revision")
    args = ap.parse_args()
    now = digests(args.seconds)
    if not args.before:
        print("\n".join(now))
        return 0
    with tempfile.TemporaryDirectory() as d:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.before], check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", d], input=archive, check=True)
        old = subprocess.run(
            [sys.executable, str(Path(__file__).resolve()), "--seconds", f"{args.seconds!r}"],
            env={**os.environ, "EYEQ_SPI_DIGEST_TREE": d}, cwd=d, check=True, capture_output=True,
            text=True).stdout.split("\n")
    differ = [a for a, b in zip(now, old, strict=False) if a != b]
    print(f"{len(now) - len(differ)} of {len(now)} digests as at {args.before}")
    for line in differ:
        print("differs:", line)
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
