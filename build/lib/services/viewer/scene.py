"""The simulator's world as a Foxglove 3D scene: the robot, its path, the targets and the
obstacles, and the transform from the world to the robot. Pure: GroundTruth in, Foxglove out.

Frames: ``world`` is the simulator's (x forward at the start, y left, z up); ``base_link`` is
the robot's (convert.ROBOT_FRAME), placed by the true pose.
"""

from __future__ import annotations

import math
from collections import deque

from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    TextPrimitive,
    Vector3,
)

from common.messages import GroundTruth
from services.viewer.convert import ROBOT_FRAME, stamp

WORLD_FRAME = "world"
PATH_SPACING_M = 0.02  # a new path point only once the robot moved this far
# Drawn sizes only: the truth carries positions, not shapes.
ROBOT_RADIUS_M = 0.25
ROBOT_HEIGHT_M = 0.3
TARGET_RADIUS_M = 0.25
TARGET_HEIGHT_M = 1.7
OBSTACLE_HEIGHT_M = 0.5
_ROBOT = Color(r=0.2, g=0.5, b=1.0, a=0.9)
_PATH = Color(r=0.2, g=0.8, b=1.0, a=1.0)
_TARGET = Color(r=1.0, g=0.6, b=0.1, a=0.8)
_OBSTACLE = Color(r=0.5, g=0.5, b=0.5, a=0.9)
_TEXT = Color(r=1.0, g=1.0, b=1.0, a=1.0)


def yaw(theta: float) -> Quaternion:
    """A rotation of ``theta`` radians about z."""
    return Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2))


class PathTrail:
    """The robot's last positions, one every PATH_SPACING_M at least, ``size`` at most."""

    def __init__(self, size: int) -> None:
        self._points: deque[tuple[float, float]] = deque(maxlen=size)

    def add(self, x: float, y: float) -> None:
        if self._points:
            px, py = self._points[-1]
            if math.hypot(x - px, y - py) < PATH_SPACING_M:
                return
        self._points.append((x, y))

    def points(self) -> list[tuple[float, float]]:
        return list(self._points)


def transforms(truth: GroundTruth) -> FrameTransforms:
    """world -> base_link at the true pose."""
    x, y, theta = truth.robot
    return FrameTransforms(
        transforms=[
            FrameTransform(
                timestamp=stamp(truth.header.stamp_ns),
                parent_frame_id=WORLD_FRAME,
                child_frame_id=ROBOT_FRAME,
                translation=Vector3(x=x, y=y, z=0.0),
                rotation=yaw(theta),
            )
        ]
    )


def _upright(x: float, y: float, radius: float, height: float, colour: Color) -> CylinderPrimitive:
    return CylinderPrimitive(
        pose=Pose(position=Vector3(x=x, y=y, z=height / 2), orientation=yaw(0.0)),
        size=Vector3(x=2 * radius, y=2 * radius, z=height),
        bottom_scale=1.0,
        top_scale=1.0,
        color=colour,
    )


def scene(truth: GroundTruth, path: list[tuple[float, float]]) -> SceneUpdate:
    """The robot (in its own frame, so it moves with the transform), its ``path``, every
    target with its id, and every obstacle (in the world frame)."""
    ts = stamp(truth.header.stamp_ns)
    robot = SceneEntity(
        timestamp=ts,
        frame_id=ROBOT_FRAME,
        id="robot",
        frame_locked=True,
        cylinders=[_upright(0.0, 0.0, ROBOT_RADIUS_M, ROBOT_HEIGHT_M, _ROBOT)],
        arrows=[
            ArrowPrimitive(
                pose=Pose(position=Vector3(x=0.0, y=0.0, z=ROBOT_HEIGHT_M), orientation=yaw(0)),
                shaft_length=0.4,
                shaft_diameter=0.05,
                head_length=0.15,
                head_diameter=0.12,
                color=_ROBOT,
            )
        ],
    )
    targets = [
        _upright(float(x), float(y), TARGET_RADIUS_M, TARGET_HEIGHT_M, _TARGET)
        for x, y in truth.targets_xy.tolist()
    ]
    labels = [
        TextPrimitive(
            pose=Pose(position=Vector3(x=x, y=y, z=TARGET_HEIGHT_M + 0.2), orientation=yaw(0)),
            billboard=True,
            font_size=14.0,
            scale_invariant=True,
            color=_TEXT,
            text=f"{name} {tid}",
        )
        for (x, y), name, tid in zip(
            truth.targets_xy.tolist(), truth.target_names, truth.target_ids, strict=True
        )
    ]
    obstacles = [
        _upright(x, y, r, OBSTACLE_HEIGHT_M, _OBSTACLE) for x, y, r in truth.obstacles.tolist()
    ]
    world = SceneEntity(
        timestamp=ts,
        frame_id=WORLD_FRAME,
        id="world",
        cylinders=[*targets, *obstacles],
        texts=labels,
        lines=[
            LinePrimitive(
                type=LinePrimitiveLineType.LineStrip,
                thickness=3.0,
                scale_invariant=True,
                points=[Point3(x=x, y=y, z=0.01) for x, y in path],
                color=_PATH,
            )
        ]
        if len(path) >= 2
        else [],
    )
    return SceneUpdate(entities=[robot, world])
