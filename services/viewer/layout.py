"""The Foxglove layout that arranges the live view's panels (deploy/foxglove/layout.json).

Built with the SDK's own layout types, so that it matches the channels by construction:
``python -m services.viewer layout`` writes it, and a unit test checks that the file shipped is
what this module builds.

    +-------------------+-------------+-------------------------+
    | Image:            | Image:      | 3D: /world/scene, /scan, |
    | /camera/image with| /camera/    | /detections/boxes3d and  |
    | /camera/annotations| depth      | /tf, following the robot |
    +--------------+----+-------------+-------+-----------------+
    | Plot: speeds | Plot: latency per stage  | Plot: FPS | Raw: controller state
    +--------------+--------------------------+-----------+

With several cameras the image panels become a column of rows, one per camera (the first
camera on top), each with its own image, annotations and depth topics (channels.camera_topics,
channels.depth_topic). The depth panel stays empty for a camera with no depth; ``depth=False``
leaves it out. The depth image is 16UC1 millimetres, drawn through the turbo colour map from 0
to :data:`DEPTH_SHOWN_MAX_MM` (change it in the panel's settings for a longer range).
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
DEPTH_SHOWN_MAX_MM = 10_000.0  # the depth panel's colour map spans 0..10 m
# The stages the metrics service times (services/metrics/figures.py), in pipeline order.
LATENCY_STAGES = (
    "capture_to_detector",
    "preprocess",
    "inference",
    "postprocess",
    "depth",
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


DEPTH_TITLE = "depth (mm, if the camera has depth)"


def _depth(topic: str, title: str) -> fl.ImagePanel:
    return fl.ImagePanel(
        title=title,
        config=fl.ImageConfig(
            image_mode=fl.ImageModeConfig(
                image_topic=topic,
                color_mode="colormap",
                color_map="turbo",
                min_value=0.0,
                max_value=DEPTH_SHOWN_MAX_MM,
            ),
        ),
    )


Panel = fl.ImagePanel | fl.SplitContainer


def _camera(cameras: Sequence[str], camera: str, depth: bool) -> Panel:
    """One camera's image panel, beside its depth panel (``depth``)."""
    first = cameras[0]
    named = "" if len(cameras) == 1 else f"{camera}: "
    image = _image(*ch.camera_topics(first, camera), named + IMAGE_TITLE)
    if not depth:
        return image
    beside = _depth(ch.depth_topic(first, camera), named + DEPTH_TITLE)
    return fl.SplitContainer(
        direction="row",
        items=[fl.SplitItem(proportion=2, content=image), fl.SplitItem(content=beside)],
    )


def _images(cameras: Sequence[str], depth: bool) -> Panel:
    """Each camera's panels: the one-camera view's alone, or a column of them."""
    if len(cameras) == 1:
        return _camera(cameras, cameras[0], depth)
    panels = [_camera(cameras, c, depth) for c in cameras]
    return fl.SplitContainer(direction="column", items=[fl.SplitItem(content=p) for p in panels])


def build(cameras: Sequence[str] = ONE_CAMERA, depth: bool = True) -> fl.Layout:
    """The layout of a stack with ``cameras`` (the first camera, stack.camera, first), with a
    depth panel beside each camera's image (``depth``)."""
    image = _images(cameras, depth)
    world = fl.ThreeDeePanel(
        title="world (simulator), laser scan, 3D detections, robot path",
        config=fl.ThreeDeeConfig(
            follow_tf="base_link",
            follow_mode="follow-position",
            fixed_frame=WORLD_FRAME,
            topics={
                ch.SCENE: fl.BaseRendererSceneUpdateTopicSettings(visible=True),
                ch.BOXES_3D: fl.BaseRendererSceneUpdateTopicSettings(visible=True),
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
    top = fl.SplitContainer(
        items=[
            fl.SplitItem(proportion=2 if depth else 1, content=image),
            fl.SplitItem(content=world),
        ]
    )
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


def layout_json(cameras: Sequence[str] = ONE_CAMERA, depth: bool = True) -> str:
    """The layout as the file holds it: indented JSON, one trailing newline."""
    return json.dumps(json.loads(build(cameras, depth).to_json()), indent=2) + "\n"


def write(
    path: Path = LAYOUT_FILE, cameras: Sequence[str] = ONE_CAMERA, depth: bool = True
) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, layout_json(cameras, depth).encode("utf-8"))
    return path
