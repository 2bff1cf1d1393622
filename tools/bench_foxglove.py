"""What a Foxglove publish costs the run's loop (``--foxglove``): one scene kind's SceneUpdate
(obstacles, road, signs or light spots: the live feed publishes one per call) built, encoded
with the SDK's schemas and handed to a live server with a client subscribed to every topic;
and the four of one DASP period (1/18 s) together. The baseline, measured in the same run:
decoding one obstacles message with its fields, which the host does for every one it
receives when anything subscribes.

    python tools/bench_foxglove.py [--rounds 300]

Prints median and spread (p10, p90, max) in ms, and the ratio of the medians.
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import sys
import threading
import time

from eyeq_spi import emulator
from eyeq_spi.codec.message import DecodedMessage
from eyeq_spi.foxglove.live import MessageFeed
from eyeq_spi.foxglove.server import ServerSink
from eyeq_spi.plot.perceived import SCENE_MESSAGES


def _scene_messages() -> tuple[dict[str, DecodedMessage], dict[str, bytes]]:
    """The scene messages of a demo at 3 s (decoded, and as sent)."""
    emu = emulator.build()
    got: dict[str, DecodedMessage] = {}
    emu.host.subscribe(lambda out: got.__setitem__(out.name, out) if out.name else None)
    emu.run_for(3.0)
    codec = emu.host.codec
    wire = {name: codec.encode_dasp(name, out.fields, 0) for name, out in got.items()
            if name in SCENE_MESSAGES}
    return {name: got[name] for name in wire}, wire


def _client(url: str, stop: threading.Event) -> threading.Thread:
    """A client subscribed to every topic, reading whatever comes (on a thread)."""
    import json

    from websockets.sync.client import connect
    from websockets.typing import Subprotocol

    def run() -> None:
        with connect(url, subprotocols=[Subprotocol("foxglove.sdk.v1")], proxy=None,
                     compression=None, max_size=None) as ws:
            channels: list[int] = []
            deadline = time.monotonic() + 5
            while len(channels) < 9 and time.monotonic() < deadline:
                msg = ws.recv(timeout=1)
                if isinstance(msg, str) and json.loads(msg).get("op") == "advertise":
                    channels += [ch["id"] for ch in json.loads(msg)["channels"]]
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": k, "channelId": cid} for k, cid in enumerate(channels)]}))
            while not stop.is_set():
                with contextlib.suppress(TimeoutError):
                    ws.recv(timeout=0.1)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def _stats(samples: list[float]) -> str:
    ms = sorted(s * 1e3 for s in samples)
    q = statistics.quantiles(ms, n=10)
    return (f"median {statistics.median(ms):.3f} ms (p10 {q[0]:.3f}, p90 {q[-1]:.3f}, "
            f"max {ms[-1]:.3f}; n={len(ms)})")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=300)
    args = ap.parse_args(argv)
    messages, wire = _scene_messages()
    emu = emulator.build()
    codec = emu.host.codec
    sink = ServerSink("127.0.0.1:0")
    feed = MessageFeed(codec, sink)
    stop = threading.Event()
    client = _client(sink.url, stop)
    deadline = time.monotonic() + 10
    while not sink.subscribed() and time.monotonic() < deadline:
        time.sleep(0.01)
    if not sink.subscribed():
        print("no client subscribed within 10 s", file=sys.stderr)
        return 1
    publish: list[float] = []
    by_kind: dict[str, list[float]] = {name: [] for name in messages}
    decode: list[float] = []
    obstacles = wire["EYEQ_VIS_OBSTACLES_MSG"]
    for k in range(args.rounds):
        t0 = time.perf_counter()
        codec.decode(obstacles, None)
        t1 = time.perf_counter()
        feed.latest = dict(messages)
        feed.scene_due.clear()
        now = k / 18.0
        t2 = t1
        while feed.latest:
            name = min(feed.latest, key=lambda kind: feed.scene_due.get(kind, now))
            feed.scene(now)
            t3 = time.perf_counter()
            by_kind[name].append(t3 - t2)
            t2 = t3
        decode.append(t1 - t0)
        publish.append(t2 - t1)
        time.sleep(0.002)  # the client and the server's threads get the CPU between rounds
    stop.set()
    client.join(timeout=5)
    sink.close()
    for name, samples in by_kind.items():
        print(f"one call, {name}: {_stats(samples)}")
    print(f"the four of a DASP period: {_stats(publish)}")
    print(f"baseline (decode one obstacles message): {_stats(decode)}")
    print(f"ratio of medians: {statistics.median(publish) / statistics.median(decode):.1f}")
    print(f"per DASP period (1/18 s = 55.6 ms): {statistics.median(publish) * 18 * 100:.1f} % "
          "of one core")
    return 0


if __name__ == "__main__":
    sys.exit(main())

