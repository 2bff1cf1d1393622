#!/usr/bin/env python3
"""tshark with the generated Lua dissector against tshark without it, on the same capture.

Input: a full-load demo capture (``demo --virtual-time --objects 15 --signs 20 --light-spots 15
--capture``, ``--duration`` seconds; 60 s is about 139 k transfers), or ``--capture FILE``.
The Lua is generated from this checkout (``--lua FILE`` measures another one, e.g. an older
version to compare with).

Each mode runs tshark without the dissector (the in-run baseline) and with it, alternately,
``--repeat`` times; every figure is CPU seconds (user + system) of the tshark process, so that
neighbours on a loaded machine do not skew it, with median and spread (min..max). The ratio is
computed per repetition (with / without) and summarised the same way. Modes:

- ``summary``: ``tshark -r CAPTURE`` (one summary line per packet, as a capture opens);
- ``stats``: ``tshark -q -z io,stat,0 -r CAPTURE`` (a statistics run, no output per packet);
- ``filter``: ``-Y 'eyeq_spi.eyeq_vision_object_t.id == 3'`` with the dissector (a payload
  member, so payloads are decoded), against ``-Y frame`` without it;
- ``details``: ``tshark -V`` (every packet's whole tree printed; not a goal, for reference);
- ``floor``: summary lines with :data:`FLOOR_LUA`, a Lua dissector that only does what every
  Lua dissector of these captures must: read each packet's interface, add its protocol item,
  set two columns. Its ratio is what Lua costs before any decoding.

    python tools/bench_wireshark.py [--duration 60] [--repeat 3] [--capture FILE] [--lua FILE]
                                    [--modes summary,stats,filter,floor,details] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

GOAL_RATIO = 5.0  # with the Lua at most 5x tshark without it (summary and stats runs)
MODES: dict[str, tuple[list[str], list[str]]] = {  # mode -> (tshark args without, with the Lua)
    "summary": ([], []),
    "stats": (["-q", "-z", "io,stat,0"], ["-q", "-z", "io,stat,0"]),
    "filter": (["-Y", "frame"], ["-Y", "eyeq_spi.eyeq_vision_object_t.id == 3"]),
    "details": (["-V"], ["-V"]),
    "floor": ([], []),
}
FLOOR_LUA = """
local p = Proto("eyeq_floor", "Lua floor")
local f_iface = Field.new("frame.interface_id")
local f_comment = Field.new("frame.comment")
local f_number = Field.new("frame.number")
local DIRS = {[0] = "h2e", [1] = "e2h"}
function p.dissector(tvb, pinfo, tree)
  local cols = pinfo.cols
  cols.protocol = "EyeQ SPI"
  local fi = f_iface()
  tree:add(p, tvb())
  cols.info = (fi and DIRS[fi.value] or "?") .. " " .. tvb:len()
  return tvb:len()
end
DissectorTable.get("wtap_encap"):add(wtap.USER0, p)
"""


def build(dirpath: Path, duration: float) -> Path:
    cap = dirpath / "full.pcapng"
    subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "demo", "--virtual-time",
                    "--duration", str(duration), "--objects", "15", "--signs", "20",
                    "--light-spots", "15", "--capture", str(cap), "--json"], check=True,
                   cwd=ROOT, capture_output=True)
    return cap


def run_once(cmd: list[str], home: Path) -> float:
    """User + system CPU seconds of one tshark run (its output is discarded)."""
    env = {**os.environ, "HOME": str(home)}
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    assert proc.stderr is not None
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = status
    if status != 0 or b"Lua: Error" in err:
        raise RuntimeError(f"{' '.join(cmd)} failed: {err.decode(errors='replace')[-500:]}")
    return float(usage.ru_utime + usage.ru_stime)


def summary(values: list[float], digits: int = 2) -> dict[str, float]:
    return {"median": round(statistics.median(values), digits),
            "min": round(min(values), digits), "max": round(max(values), digits)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--capture", type=Path)
    ap.add_argument("--lua", type=Path, help="a dissector file (default: generate it)")
    ap.add_argument("--modes", default="summary,stats,filter,floor,details")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    tshark = shutil.which("tshark")
    if tshark is None:
        print("tshark is not installed (Debian: apt-get install tshark)", file=sys.stderr)
        return 2
    modes = [m for m in args.modes.split(",") if m]
    unknown = [m for m in modes if m not in MODES]
    if unknown or args.repeat < 1:
        print(f"unknown modes {unknown} (known: {', '.join(MODES)}) or --repeat < 1",
              file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cap = args.capture or build(work, args.duration)
        lua = args.lua
        if lua is None:
            from eyeq_spi.wireshark import generate_lua

            lua = work / "eyeq_spi.lua"
            lua.write_text(generate_lua(), encoding="utf-8")
        floor = work / "floor.lua"
        floor.write_text(FLOOR_LUA, encoding="utf-8")
        frames = sum(1 for _ in subprocess.run(
            [tshark, "-r", str(cap), "-T", "fields", "-e", "frame.number"], check=True,
            capture_output=True, text=True, env={**os.environ, "HOME": tmp}).stdout.splitlines())
        out: dict[str, object] = {"capture": str(cap) if args.capture else
                                  f"demo full load, {args.duration:g} s", "frames": frames,
                                  "repeat": args.repeat, "goal_ratio": GOAL_RATIO}
        for mode in modes:
            without, with_lua = MODES[mode]
            base_cmd = [tshark, "-n", "-r", str(cap), *without]
            script = floor if mode == "floor" else lua
            lua_cmd = [tshark, "-n", "-r", str(cap), "-X", f"lua_script:{script}", *with_lua]
            base, lua_s, ratio = [], [], []
            for _ in range(args.repeat):
                b = run_once(base_cmd, work)
                w = run_once(lua_cmd, work)
                base.append(b)
                lua_s.append(w)
                ratio.append(w / b)
            out[mode] = {"tshark_cpu_s": summary(base), "with_lua_cpu_s": summary(lua_s),
                         "ratio": summary(ratio, 1),
                         "lua_us_per_frame": round(
                             (statistics.median(lua_s) - statistics.median(base)) / frames * 1e6,
                             1)}
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"{out['capture']}: {frames} frames, {args.repeat} runs each, CPU-s median (min..max)")
    print(f"{'mode':8} {'tshark':>18} {'with the Lua':>18} {'ratio':>16} {'Lua us/frame':>13}")
    for mode in modes:
        row = out[mode]
        assert isinstance(row, dict)

        def fmt(s: dict[str, float]) -> str:
            return f"{s['median']:g} ({s['min']:g}..{s['max']:g})"

        print(f"{mode:8} {fmt(row['tshark_cpu_s']):>18} {fmt(row['with_lua_cpu_s']):>18} "
              f"{fmt(row['ratio']):>16} {row['lua_us_per_frame']:>13}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
