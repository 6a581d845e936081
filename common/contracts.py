"""The stack's shared vocabularies and the shapes of the JSON it writes, in one module.

Enums name what used to be bare strings (a controller mode, a state, a backend); each is a
``StrEnum``, so it equals its string on the wire, in TOML and in JSON. The ``TypedDict``s are
the contracts of the JSON answers (the metrics query, a scenario's figures, a benchmark, a
recorded session): the writer builds them, every reader reads them through these types.
"""

from __future__ import annotations

from enum import StrEnum


class ControllerMode(StrEnum):
    TRACK = "track"  # turn towards the most central target; forward while centred
    FOLLOW = "follow"  # lock onto one target and keep a distance


class ControllerState(StrEnum):
    """What the controller is doing; ControllerStatus.state carries it."""

    STALE = "stale"  # no fresh detections: zero (dead-man)
    ESTOP = "estop"  # the e-stop is latched: zero
    SEARCHING = "searching"  # no target in view: zero
    HOLDING = "holding"  # target briefly unseen: keep the last aim
    TURNING = "turning"  # target off-centre: turn only
    TRACKING = "tracking"  # track mode, centred: forward
    FOLLOWING = "following"  # follow mode, centred and clear: forward
    BLOCKED = "blocked"  # something ahead, or no scan: turn only
    ARRIVED = "arrived"  # at the follow distance: turn only
    FAULT = "fault"  # a non-finite command was computed: zero
    STOPPED = "stopped"  # shutting down: zero


class DistanceSource(StrEnum):
    BOX = "box"  # from the box height and the target's known height
    LASER = "laser"  # the laser's range in the target's bearing


class BackendName(StrEnum):
    ONNX = "onnx"  # ONNX Runtime on the CPU
    TENSORRT = "tensorrt"
    CUDA = "cuda"  # our ONNX interpreter on PyTorch CUDA
    AUTO = "auto"  # tensorrt, then cuda, then onnx
