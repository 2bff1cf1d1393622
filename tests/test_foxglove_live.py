"""A live ``demo --foxglove`` checked by a Foxglove WebSocket client in another process:
it subscribes to the obstacles' scene topic and receives SceneUpdates at about the DASP rate
(18 Hz), each with the ego car and boxes in the vehicle frame; the log topic carries the
host's transitions. Bounded in wall time; robust to a loaded machine (rates within a wide band)."""

from __future__ import annotations

import queue
import subprocess
import threading

import pytest

pytest.importorskip("foxglove", reason="the [foxglove] extra (foxglove-sdk) is not installed")
pytest.importorskip("websockets", reason="the websockets client is not installed (test extra)")

from tests.foxglove_client import Client
from tests.sim_proc import CLI, ROOT

LISTEN_S = 3.0
DASP_HZ = 18.0


def _address(stream: object, timeout: float = 60.0) -> str:
    found: queue.Queue[str] = queue.Queue()

    def read() -> None:
        for line in stream:  # type: ignore[attr-defined]
            if line.startswith("FOXGLOVE ws://"):
                found.put(line.split()[1])
                return

    threading.Thread(target=read, daemon=True).start()
    return found.get(timeout=timeout)


@pytest.mark.realtime
def test_demo_serves_scene_updates_at_the_dasp_rate() -> None:
    demo = subprocess.Popen([*CLI, "demo", "--duration", "12", "--foxglove", "127.0.0.1:0",
                             "--json"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        url = _address(demo.stderr)
        assert url.startswith("ws://127.0.0.1:") and not url.endswith(":0")
        client = Client(url)
        try:
            client.wait_for(["/scene/obstacles", "/log", "/tf"])
            client.subscribe("/scene/obstacles", 1)
            client.subscribe("/log", 2)
            scene_update = client.decoder("/scene/obstacles")
            log = client.decoder("/log")
            got = client.receive(LISTEN_S)
        finally:
            client.close()
    finally:
        demo.terminate()  # SIGTERM ends the demo cleanly
        demo.communicate(timeout=60)
    scenes = [(arrived, payload) for topic, arrived, _, payload in got
              if topic == "/scene/obstacles"]
    assert len(scenes) >= 10, f"{len(scenes)} scene updates in {LISTEN_S} s"
    # at about the DASP rate: never faster than the stream, and not starved (a loaded machine
    # delays some, the demo catches up)
    span = scenes[-1][0] - scenes[0][0]
    rate = (len(scenes) - 1) / span
    assert DASP_HZ * 0.4 < rate < DASP_HZ * 1.3, f"{rate:.1f} Hz"
    update = scene_update.FromString(scenes[-1][1])
    ids = {entity.id for entity in update.entities}
    assert "ego" in ids and any(i.startswith("obstacle/") for i in ids), ids
    boxes = [e for e in update.entities if e.id.startswith("obstacle/")]
    assert all(e.frame_id == "vehicle" and len(e.cubes) == 1 for e in boxes)
    # the simulated EyeQ's objects are on the road ahead and around the car
    assert all(-200 < e.cubes[0].pose.position.x < 250 and e.cubes[0].size.x > 0 for e in boxes)
    lines = [log.FromString(payload).message for topic, _, _, payload in got if topic == "/log"]
    # the bring-up happened before the client subscribed; the log topic is live either way
    assert all(isinstance(line, str) for line in lines)
