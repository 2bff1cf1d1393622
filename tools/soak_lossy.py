#!/usr/bin/env python3
"""Lossy-channel soak: host emulator and simulated EyeQ through the memory pair's
fault hook, in virtual time. Prints the injected faults per class, the receiver counters that
account for them (expected = observed for every exact rule), the messages sent, delivered and
corrupted, and whether Running Vision was reached and held. Exit 1 if any check fails.

    python tools/soak_lossy.py --duration 60            # the default profile, 60 s in vision
    python tools/soak_lossy.py --loss 0.05 --from-start # 5 % frame loss from power-up
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from eyeq_spi.errors import UsageError
from eyeq_spi.faults.channel import FaultProfile
from eyeq_spi.faults.soak import BOUNDED, EXACT, SoakConfig, run_soak


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0, help="virtual seconds with faults")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--loss", type=float, default=None,
                    help="total frame loss (drop raised above the default profile)")
    ap.add_argument("--from-start", action="store_true", help="faults from power-up")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    try:
        profile = FaultProfile() if args.loss is None else FaultProfile.with_loss(args.loss)
    except UsageError as exc:
        ap.error(str(exc))  # one line, exit 2
    t0 = time.perf_counter()
    r = run_soak(SoakConfig(profile=profile, seed=args.seed, duration=args.duration,
                            faults_from_start=args.from_start))
    wall = time.perf_counter() - t0
    exact_ok = all(a.ok for a in r.accounting.values())
    # with faults from power-up a lost boot status can cost a reset of the EyeQ, which moves
    # NUMs: the accounting of such a run is reported, not judged
    reset = bool(r.host["eyeq_resets"] or r.host["boot_failures"])
    ok = r.corrupted == 0 and r.held and (exact_ok or reset)
    if args.json:
        print(json.dumps({**r.as_dict(), "exact_ok": exact_ok, "ok": ok}, default=str))
        return 0 if ok else 1
    print(f"{r.virtual_s:.1f} s virtual in {wall:.1f} s wall; frames {r.frames}")
    print(f"vision reached at {r.reached_vision_at} s, held: {r.held}, final {r.final_state}")
    for side, acc in r.accounting.items():
        print(f"into {side}: injected {dict(sorted(acc.injected.items()))}")
        for name in (*EXACT, *BOUNDED):
            obs = acc.observed[name]
            rule = (f"in {list(acc.bounds[name])}" if name in acc.bounds
                    else f"expected {acc.expected[name]}")
            print(f"  {name:22s} {obs:7d}  {rule}")
        print(f"  (transport NAKs 0x011 after a loss: {acc.observed['formatNaks']})")
    for direction, m in r.messages.items():
        print(f"{direction}: {m['sent']} sent, {m['delivered']} delivered, "
              f"{m['corrupted']} corrupted")
    print(f"host: {json.dumps({k: v for k, v in r.host.items() if k != 'transitions'})}")
    print("OK" if ok else "FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
