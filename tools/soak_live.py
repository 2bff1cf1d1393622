#!/usr/bin/env python3
"""Live soak: ``eyeq-spi sim`` and ``eyeq-spi host`` as two processes in real time, at full load
(``--objects 15 --signs 20 --light-spots 15``), over TCP or a pty, for ``--duration`` seconds.

Prints both closing summaries' loss figures (E2E errors, send failures, transport aborts, DASP
counter gaps, stale streams, MESP timeouts), the send -> ACK latency of each side (p50, p99.9,
max) and the CPU each process used, as one JSON object. Exits 1 if either side lost anything.

    python3 tools/soak_live.py --duration 600 --transport tcp   # the 10-minute run (README)
    python3 tools/soak_live.py --duration 45                    # what CI runs
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

LOAD = ["--objects", "15", "--signs", "20", "--light-spots", "15"]
LOSS_KEYS = ("e2e_errors", "dasp_counter_gaps", "stale_streams", "transport_aborts")


def _cli() -> list[str]:
    return [sys.executable, "-m", "eyeq_spi.cli"]


def soak(duration: float, transport: str) -> dict[str, Any]:
    listen = ["--listen", "tcp://127.0.0.1:0"] if transport == "tcp" else ["--pty"]
    sim = subprocess.Popen(
        [*_cli(), "sim", *listen, "--duration", str(duration + 15), "--accept-timeout", "30",
         "--json", *LOAD], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert sim.stderr is not None
    seen = []
    for line in sim.stderr:  # LISTEN URL or PTY PATH comes on stderr (stdout: the summary)
        first = line.split()
        if len(first) == 2 and first[0] in ("LISTEN", "PTY"):
            break
        seen.append(line)
    else:
        sim.kill()
        raise SystemExit(f"sim did not start: {''.join(seen)}")
    port = first[1]
    with tempfile.TemporaryDirectory() as tmp:
        host = subprocess.run(
            [*_cli(), "host", "--port", port, "--duration", str(duration), "--json",
             "--nvm", str(Path(tmp) / "nvm.json")],
            capture_output=True, text=True, timeout=duration + 60)
    time.sleep(0.5)
    sim.send_signal(subprocess.signal.SIGTERM)  # type: ignore[attr-defined]
    try:
        sim_out, _ = sim.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        sim.kill()
        sim_out, _ = sim.communicate()
    h = json.loads(host.stdout.strip().splitlines()[-1])
    s = json.loads(sim_out.strip().splitlines()[-1])
    return {"transport": transport, "duration_s": duration, "host": _figures(h),
            "sim": _figures(s), "host_problem": h["problem"], "host_rc": host.returncode}


def _figures(out: dict[str, Any]) -> dict[str, Any]:
    return {
        "ok": out["ok"], "problem": out["problem"], "state": out["state"],
        "cpu_s": out["cpu_s"], "cpu_per_s": round(out["cpu_s"] / max(out["elapsed_s"], 1e-9), 4),
        "send_failures": out["link"]["sendFailedErrorCounter"],
        "mesp_timeouts": out["mesp"]["timeouts"],
        "ack_latency_ms": out["ack_latency_ms"], "link": out["link"],
        "scheduling": out.get("scheduling"),
        **{k: out[k] for k in LOSS_KEYS},
    }


def lossless(side: dict[str, Any]) -> bool:
    return not (side["e2e_errors"] or side["dasp_counter_gaps"] or side["stale_streams"]
                or side["transport_aborts"] or side["send_failures"] or side["mesp_timeouts"])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--transport", choices=("tcp", "pty"), default="tcp")
    args = ap.parse_args()
    r = soak(args.duration, args.transport)
    print(json.dumps(r, indent=1, sort_keys=True))
    return 0 if lossless(r["host"]) and lossless(r["sim"]) else 1


if __name__ == "__main__":
    sys.exit(main())
