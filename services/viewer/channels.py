"""The live view's Foxglove channels: their topics, and the JSON schemas of the plottable ones.

Typed channels (protobuf, Foxglove's own schemas) carry each camera's image and its
annotations, the depth image of each camera announced with depth (made when it is first
announced so), the 3D boxes of the detections with depth, the scan, each depth camera's
virtual scan (made with its first), the transforms and the 3D scene; the command, the
controller's state and the metrics are JSON with a JSON schema, so that Foxglove's Plot panel
can plot any number in them. The layout (layout.py) names the same topics.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import Any

import foxglove
from foxglove.channels import (
    CompressedImageChannel,
    FrameTransformsChannel,
    ImageAnnotationsChannel,
    LaserScanChannel,
    RawImageChannel,
    SceneUpdateChannel,
)

# The first camera's (stack.camera); each further camera's: camera_topics().
IMAGE = "/camera/image"
ANNOTATIONS = "/camera/annotations"
SCAN = "/scan"
TF = "/tf"
SCENE = "/world/scene"
BOXES_3D = "/detections/boxes3d"  # every camera's 3D boxes, an entity per camera
CMD_VEL = "/cmd_vel"
CONTROLLER = "/controller/status"
METRICS = "/metrics"


def camera_topics(first: str, camera: str) -> tuple[str, str]:
    """The image and annotations topics of ``camera``: IMAGE and ANNOTATIONS for the first
    camera (``first``, stack.camera), as a one-camera view has always named them, and
    ``/camera/<name>/image``, ``/camera/<name>/annotations`` for each further one."""
    if camera == first:
        return IMAGE, ANNOTATIONS
    return f"/camera/{camera}/image", f"/camera/{camera}/annotations"


def virtual_scan_topic(camera: str) -> str:
    """The topic of ``camera``'s virtual scan (what the controller judged as obstacles from its
    depth): ``/scan/virtual/<camera>``, beside the laser's ``/scan``."""
    return f"{SCAN}/virtual/{camera}"


def depth_topic(first: str, camera: str) -> str:
    """The depth image topic of ``camera``: ``/camera/depth`` for the first camera (``first``),
    ``/camera/<name>/depth`` for each further one, beside its image."""
    return "/camera/depth" if camera == first else f"/camera/{camera}/depth"


_NUMBER = {"type": "number"}
_PERCENTILES = {
    "type": "object",
    "properties": {k: _NUMBER for k in ("p50", "p95", "p99", "mean", "count")},
}

CMD_VEL_SCHEMA: dict[str, Any] = {
    "title": "stack.CmdVel",
    "type": "object",
    "properties": {
        "linear": {"type": "number", "description": "forward speed, m/s"},
        "angular": {"type": "number", "description": "turn rate, rad/s, counter-clockwise"},
        "input_stamp_ns": {"type": "integer", "description": "capture stamp it reacts to"},
        "source": {"type": "string"},
    },
}
CONTROLLER_SCHEMA: dict[str, Any] = {
    "title": "stack.ControllerStatus",
    "type": "object",
    "properties": {
        "mode": {"type": "string"},
        "state": {"type": "string"},
        "target": {"type": "string", "description": "the class it follows"},
        "track_id": {"type": "integer", "description": "the locked track, -1 for none"},
        "locked": {"type": "boolean"},
        "reason": {"type": "string"},
    },
}
METRICS_SCHEMA: dict[str, Any] = {
    "title": "stack.Metrics",
    "type": "object",
    "properties": {
        "fps": {"type": "number", "description": "frames detected per second"},
        "detections_per_frame": _NUMBER,
        "dropped_frames": {"type": "integer"},
        "drop_rate": _NUMBER,
        "bad_input": {"type": "integer", "description": "bad messages, all services"},
        "depth_frames": {"type": "integer", "description": "depth images the detector took"},
        "depth_unpaired": {
            "type": "integer",
            "description": "colour frames of a depth camera with no depth image in time",
        },
        "latency_ms": {
            "type": "object",
            "description": "per stage (inference, end_to_end, ...): percentiles in ms",
            "additionalProperties": _PERCENTILES,
        },
    },
}


class CameraChannels:
    """One camera's image and the annotations drawn over it."""

    def __init__(self, context: foxglove.Context, image_topic: str, annotations_topic: str) -> None:
        self.image = CompressedImageChannel(image_topic, context=context)
        self.annotations = ImageAnnotationsChannel(annotations_topic, context=context)

    def watched(self) -> bool:
        """Whether a client subscribes to the image or its annotations (else nothing is
        encoded)."""
        return self.image.has_sinks() or self.annotations.has_sinks()


class Channels:
    """Every channel of the view, in one Foxglove context (one server): ``cameras`` by name,
    the first camera (stack.camera) first; a camera's depth channel once asked for
    (:meth:`depth`)."""

    def __init__(self, context: foxglove.Context, cameras: Sequence[str]) -> None:
        first = self.first = cameras[0]
        self.context = context
        self.cameras = {c: CameraChannels(context, *camera_topics(first, c)) for c in cameras}
        self.scan = LaserScanChannel(SCAN, context=context)
        self.tf = FrameTransformsChannel(TF, context=context)
        self.scene = SceneUpdateChannel(SCENE, context=context)
        self.boxes = SceneUpdateChannel(BOXES_3D, context=context)
        self._depth: dict[str, RawImageChannel] = {}
        self._virtual: dict[str, LaserScanChannel] = {}
        self._made = threading.Lock()  # channels made on first use, from any bus thread
        self.cmd_vel = foxglove.Channel(CMD_VEL, schema=CMD_VEL_SCHEMA, context=context)
        self.controller = foxglove.Channel(CONTROLLER, schema=CONTROLLER_SCHEMA, context=context)
        self.metrics = foxglove.Channel(METRICS, schema=METRICS_SCHEMA, context=context)

    def virtual_scan(self, camera: str) -> LaserScanChannel:
        """``camera``'s virtual scan channel, made (advertised) with its first scan: only the
        depth cameras of a controller that reads depth have one."""
        with self._made:
            channel = self._virtual.get(camera)
            if channel is None:
                topic = virtual_scan_topic(camera)
                channel = self._virtual[camera] = LaserScanChannel(topic, context=self.context)
            return channel

    def depth(self, camera: str) -> RawImageChannel:
        """``camera``'s depth image channel, made (advertised) on the first call: only the
        cameras announced with depth have one."""
        channel = self._depth.get(camera)
        if channel is None:
            topic = depth_topic(self.first, camera)
            channel = self._depth[camera] = RawImageChannel(topic, context=self.context)
        return channel
