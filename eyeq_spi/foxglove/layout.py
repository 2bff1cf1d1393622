"""The Foxglove layout for the topics of :mod:`eyeq_spi.foxglove.topics`, built with the SDK's
``foxglove.layouts``: the 3D panel (following the vehicle frame, the scene topics shown) on the
left; on the right the plots (ego speed and yaw rate, stream rates, ACK latency) over the log.
Foxglove imports it from its layout menu ("Import from file...")."""

from __future__ import annotations

from typing import Any

from eyeq_spi.errors import MissingExtra
from eyeq_spi.foxglove import topics
from eyeq_spi.plot.vehicle_frame import FRAME


def _plot(fl: Any, title: str, series: list[tuple[str, str]]) -> Any:
    return fl.PlotPanel(title=title, config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=value, label=label, timestamp_method="receiveTime")
               for value, label in series], show_legend=True))


def layout_json() -> str:
    """The layout as Foxglove's JSON."""
    try:
        import foxglove.layouts as fl
    except ImportError:
        raise MissingExtra("foxglove", "the Foxglove layout") from None
    scene = fl.ThreeDeePanel(title="EyeQ scene", config=fl.ThreeDeeConfig(
        follow_tf=FRAME, follow_mode="follow-pose",
        camera_state=fl.ThreeDeeCameraState(distance=60.0, perspective=True, phi=50.0,
                                            target_offset=(20.0, 0.0, 0.0), theta_offset=0.0),
        topics={topic: fl.BaseRendererSceneUpdateTopicSettings(visible=True)
                for topic in topics.SCENE_TOPICS.values()}))
    plots = [
        _plot(fl, "Ego", [(f"{topics.EGO}.speed", "speed (m/s)"),
                          (f"{topics.EGO}.yaw_rate", "yaw rate (rad/s)")]),
        _plot(fl, "Scene streams (Hz)", [(f"{topics.STREAMS}.{name}",
                                          name.removeprefix("EYEQ_VIS_").removesuffix("_MSG"))
                                         for name in topics.SCENE_TOPICS]),
        _plot(fl, "ACK latency (ms)", [(f"{topics.ACK_LATENCY}.p50_ms", "p50"),
                                       (f"{topics.ACK_LATENCY}.max_ms", "max")]),
        fl.LogPanel(title="Link and host", config=fl.LogConfig(topic_to_render=topics.LOG)),
    ]
    right = fl.SplitContainer(direction="column",
                              items=[fl.SplitItem(content=panel) for panel in plots])
    root = fl.SplitContainer(direction="row", items=[
        fl.SplitItem(content=scene, proportion=2.0), fl.SplitItem(content=right)])
    return str(fl.Layout(content=root).to_json())
