"""A top view of the Foxglove scene in an MCAP written by ``eyeq-spi export --mcap``, drawn
from its ``foxglove.SceneUpdate`` messages (decoded with the schemas in the file, the SDK's)
as Foxglove's 3D panel would place them: boxes, line strips, sign plates, light spots and
labels, in the vehicle frame (x forward up the page, y left to the left). It is not a
screenshot of Foxglove; it shows the same messages.

    python tools/foxglove_picture.py drive.mcap --at 3 -o docs/img/foxglove-scene.png
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

SCENE_TOPICS = ("/scene/lanes", "/scene/signs", "/scene/lights", "/scene/obstacles")


def scene_at(path: str, at: float) -> dict[str, dict[str, Any]]:
    """topic -> entity id -> entity, every SceneUpdate applied in order up to ``at`` seconds
    after the file's first message, the capture's first transfer (as ``eyeq-spi plot --at``);
    deletions too; lifetimes are not applied: a stopped stream's last entities stay."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    shown: dict[str, dict[str, Any]] = {topic: {} for topic in SCENE_TOPICS}
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        stats = summary.statistics if summary is not None else None
        start = stats.message_start_time if stats is not None else 0
        for _, channel, message, update in reader.iter_decoded_messages(topics=SCENE_TOPICS):
            if message.log_time - start > at * 1e9:
                break
            entities = shown[channel.topic]
            for deletion in update.deletions:
                entities.pop(deletion.id, None)
            for entity in update.entities:
                entities[entity.id] = entity
    return shown


def _yaw(orientation: Any) -> float:
    return 2.0 * math.atan2(orientation.z, orientation.w)


def _rgba(colour: Any) -> tuple[float, float, float, float]:
    return colour.r, colour.g, colour.b, colour.a


def _corners(x: float, y: float, length: float, width: float,
             yaw: float) -> list[tuple[float, float]]:
    """(y, x) of a box's corners: the page's horizontal axis is y (left on the left)."""
    c, s = math.cos(yaw), math.sin(yaw)
    out = []
    for a, b in ((length / 2, width / 2), (-length / 2, width / 2), (-length / 2, -width / 2),
                 (length / 2, -width / 2)):
        out.append((y + a * s + b * c, x + a * c - b * s))
    return out


def draw(shown: dict[str, dict[str, Any]], out: str, *, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon

    fig, ax = plt.subplots(figsize=(6.4, 9.0), dpi=100)
    ax.set_facecolor("#f2f2f2")
    for topic in SCENE_TOPICS:
        for entity in shown[topic].values():
            for line in entity.lines:
                px, py = line.pose.position.x, line.pose.position.y
                yaw = _yaw(line.pose.orientation)
                c, s = math.cos(yaw), math.sin(yaw)
                xs = [px + p.x * c - p.y * s for p in line.points]
                ys = [py + p.x * s + p.y * c for p in line.points]
                if line.type == 1 and xs:  # LINE_LOOP
                    xs, ys = [*xs, xs[0]], [*ys, ys[0]]
                ax.plot(ys, xs, color=_rgba(line.color)[:3], lw=1.6 if topic == "/scene/lanes"
                        else 1.2, zorder=3 if topic == "/scene/obstacles" else 1)
            for cube in entity.cubes:
                pos = cube.pose.position
                corners = _corners(pos.x, pos.y, max(cube.size.x, 0.3), max(cube.size.y, 0.3),
                                   _yaw(cube.pose.orientation))
                ax.add_patch(Polygon(corners, closed=True, facecolor=_rgba(cube.color),
                                     edgecolor="black", lw=0.5, zorder=2))
            for sphere in entity.spheres:
                pos = sphere.pose.position
                ax.add_patch(Circle((pos.y, pos.x), max(sphere.size.x, 0.6) / 2,
                                    facecolor=_rgba(sphere.color)[:3], edgecolor="black",
                                    lw=0.5, zorder=2))
            for text in entity.texts:
                pos = text.pose.position
                ax.annotate(text.text, (pos.y, pos.x), xytext=(6, 2), textcoords="offset points",
                            fontsize=7, zorder=4)
    ax.set_xlim(15, -15)  # y left positive: left of the car on the left of the page
    ax.set_ylim(-10, 100)
    ax.set_aspect("equal")
    ax.set_xlabel("y (m, left positive)")
    ax.set_ylabel("x (m, forward)")
    ax.set_title(title, fontsize=10)
    ax.grid(True, lw=0.3)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap")
    ap.add_argument("--at", type=float, default=3.0,
                    help="seconds after the capture's first transfer")
    ap.add_argument("-o", "--out", default="foxglove-scene.png")
    args = ap.parse_args(argv)
    shown = scene_at(args.mcap, args.at)
    counts = ", ".join(f"{topic} {len(entities)}" for topic, entities in shown.items())
    draw(shown, args.out, title=f"The Foxglove scene at {args.at:g} s, from above\n"
         "(foxglove.SceneUpdate entities, vehicle frame)")
    print(f"wrote {args.out} ({counts})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
