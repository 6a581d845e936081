"""The live view's Foxglove channels: their topics, and the JSON schemas of the plottable ones.

Typed channels (protobuf, Foxglove's own schemas) carry the image, its annotations, the scan,
the transforms and the 3D scene; the command, the controller's state and the metrics are JSON
with a JSON schema, so that Foxglove's Plot panel can plot any number in them. The layout
(layout.py) names the same topics.
"""

from __future__ import annotations

from typing import Any

import foxglove
from foxglove.channels import (
    CompressedImageChannel,
    FrameTransformsChannel,
    ImageAnnotationsChannel,
    LaserScanChannel,
    SceneUpdateChannel,
)

IMAGE = "/camera/image"
ANNOTATIONS = "/camera/annotations"
SCAN = "/scan"
TF = "/tf"
SCENE = "/world/scene"
CMD_VEL = "/cmd_vel"
CONTROLLER = "/controller/status"
METRICS = "/metrics"

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
        "latency_ms": {
            "type": "object",
            "description": "per stage (inference, end_to_end, ...): percentiles in ms",
            "additionalProperties": _PERCENTILES,
        },
    },
}


class Channels:
    """Every channel of the view, in one Foxglove context (one server)."""

    def __init__(self, context: foxglove.Context) -> None:
        self.image = CompressedImageChannel(IMAGE, context=context)
        self.annotations = ImageAnnotationsChannel(ANNOTATIONS, context=context)
        self.scan = LaserScanChannel(SCAN, context=context)
        self.tf = FrameTransformsChannel(TF, context=context)
        self.scene = SceneUpdateChannel(SCENE, context=context)
        self.cmd_vel = foxglove.Channel(CMD_VEL, schema=CMD_VEL_SCHEMA, context=context)
        self.controller = foxglove.Channel(CONTROLLER, schema=CONTROLLER_SCHEMA, context=context)
        self.metrics = foxglove.Channel(METRICS, schema=METRICS_SCHEMA, context=context)

    def watched(self) -> bool:
        """Whether a client subscribes to the image or its annotations (else nothing is
        encoded)."""
        return self.image.has_sinks() or self.annotations.has_sinks()
