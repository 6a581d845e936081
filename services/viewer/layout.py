"""The Foxglove layout that arranges the live view's panels (deploy/foxglove/layout.json).

Built with the SDK's own layout types, so that it matches the channels by construction:
``python -m services.viewer layout`` writes it, and a unit test checks that the file shipped is
what this module builds.

    +----------------------------+------------------------+
    | Image: /camera/image with  | 3D: /world/scene, /scan |
    | /camera/annotations        | and /tf, following the  |
    |                            | robot                   |
    +--------------+-------------+------------+-----------+
    | Plot: speeds | Plot: latency per stage  | Plot: FPS | Raw: controller state
    +--------------+--------------------------+-----------+

With several cameras the image panel becomes a column of them, one per camera (the first camera
on top), each with its own image and annotations topics (channels.camera_topics).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import foxglove.layouts as fl

from common.files import atomic_write_bytes
from common.settings import REPO_ROOT, StackSettings
from services.viewer import channels as ch
from services.viewer.scene import WORLD_FRAME

LAYOUT_FILE = REPO_ROOT / "deploy" / "foxglove" / "layout.json"
ONE_CAMERA = (StackSettings().camera,)  # the shipped layout's: one camera
# The stages the metrics service times (services/metrics/aggregate.py), in pipeline order.
LATENCY_STAGES = (
    "capture_to_detector",
    "preprocess",
    "inference",
    "postprocess",
    "capture_to_detections",
    "detections_to_command",
    "end_to_end",
)


def _plot(title: str, paths: list[tuple[str, str]], y_label: str) -> fl.PlotPanel:
    return fl.PlotPanel(
        title=title,
        config=fl.PlotConfig(
            paths=[fl.PlotSeries(value=value, label=label) for value, label in paths],
            y_axis_label=y_label,
            show_legend=True,
            following_view_width=60.0,  # seconds of history in view
        ),
    )


IMAGE_TITLE = "camera and detections (the locked target in red)"


def _image(image_topic: str, annotations_topic: str, title: str) -> fl.ImagePanel:
    return fl.ImagePanel(
        title=title,
        config=fl.ImageConfig(
            image_mode=fl.ImageModeConfig(
                image_topic=image_topic,
                annotations={annotations_topic: fl.ImageAnnotationSettings(visible=True)},
                # Each image is sent with the detections made on it, under the same stamp.
                synchronize=True,
            ),
        ),
    )


def _images(cameras: Sequence[str]) -> fl.ImagePanel | fl.SplitContainer:
    """One image panel per camera: the one-camera view's panel alone, or a column of them."""
    if len(cameras) == 1:
        return _image(ch.IMAGE, ch.ANNOTATIONS, IMAGE_TITLE)
    panels = [_image(*ch.camera_topics(cameras[0], c), f"{c}: {IMAGE_TITLE}") for c in cameras]
    return fl.SplitContainer(direction="column", items=[fl.SplitItem(content=p) for p in panels])


def build(cameras: Sequence[str] = ONE_CAMERA) -> fl.Layout:
    """The layout of a stack with ``cameras`` (the first camera, stack.camera, first)."""
    image = _images(cameras)
    world = fl.ThreeDeePanel(
        title="world (simulator), laser scan, robot path",
        config=fl.ThreeDeeConfig(
            follow_tf="base_link",
            follow_mode="follow-position",
            fixed_frame=WORLD_FRAME,
            topics={
                ch.SCENE: fl.BaseRendererSceneUpdateTopicSettings(visible=True),
                ch.SCAN: fl.BaseRendererLaserScanTopicSettings(
                    visible=True, point_size=4.0, color_mode="flat", flat_color="#ff4040"
                ),
            },
        ),
    )
    speeds = _plot(
        "command",
        [(f"{ch.CMD_VEL}.linear", "linear m/s"), (f"{ch.CMD_VEL}.angular", "angular rad/s")],
        "m/s, rad/s",
    )
    latency = _plot(
        "latency p50 per stage",
        [(f"{ch.METRICS}.latency_ms.{s}.p50", s) for s in LATENCY_STAGES],
        "ms",
    )
    fps = _plot(
        "throughput",
        [(f"{ch.METRICS}.fps", "FPS"), (f"{ch.METRICS}.detections_per_frame", "det/frame")],
        "per s",
    )
    state = fl.RawMessagesPanel(
        title="controller", config=fl.RawMessagesConfig(topic_path=ch.CONTROLLER)
    )
    top = fl.SplitContainer(items=[fl.SplitItem(content=p) for p in (image, world)])
    bottom = fl.SplitContainer(
        direction="row",
        items=[fl.SplitItem(content=p) for p in (speeds, latency, fps, state)],
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction="column",
            items=[
                fl.SplitItem(proportion=2, content=top),
                fl.SplitItem(proportion=1, content=bottom),
            ],
        )
    )


def layout_json(cameras: Sequence[str] = ONE_CAMERA) -> str:
    """The layout as the file holds it: indented JSON, one trailing newline."""
    return json.dumps(json.loads(build(cameras).to_json()), indent=2) + "\n"


def write(path: Path = LAYOUT_FILE, cameras: Sequence[str] = ONE_CAMERA) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, layout_json(cameras).encode("utf-8"))
    return path
