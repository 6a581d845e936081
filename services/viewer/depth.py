"""Depth in the live view: a depth image as Foxglove's, each detection's 3D box in its camera's
optical frame, and where each camera stands on the robot. Pure: messages in, Foxglove out.

Frames: a camera's optical frame (REP 103: x right, y down, z forward) is named by the frame id
its images carry (``optical_frames``); the transform from the robot's ``base_link`` (x forward,
y left, z up) to it is the camera's announced mounting, ``perception.Mounting.of`` (the one
transform the controller, the scan and the bridge use too): ``x_m`` forward, ``y_m`` left,
``height_m`` up, turned ``yaw_deg`` counter-clockwise, looking level. The depth columns'
names are perception's.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping

import cv2
import numpy as np
import numpy.typing as npt
from foxglove.messages import (
    Color,
    CubePrimitive,
    Duration,
    FrameTransform,
    FrameTransforms,
    Pose,
    Quaternion,
    RawImage,
    SceneEntity,
    SceneUpdate,
    TextPrimitive,
    Vector3,
)

from common.annotate import class_colour
from common.messages import CameraAnnouncement, DepthFrame, Detections
from perception import DEPTH_CENTRE as CENTRE
from perception import DEPTH_COLUMNS as COLUMNS
from perception import DEPTH_DISTANCE as DISTANCE
from perception import DEPTH_SIZE as SIZE
from perception import Mounting, depth_metres
from services.viewer.convert import ROBOT_FRAME, scaled_size, stamp

#: The depth image as sent: 16-bit millimetres, 0 where there is no reading (as a RealSense
#: publishes it): Foxglove's Image panel maps it through a colour map between its min and max.
DEPTH_ENCODING = "16UC1"
MAX_DEPTH_MM = 65535  # the farthest a 16UC1 pixel holds (65.5 m); farther readings clip to it
BOX_ALPHA = 0.35  # a cube's fill: the object inside it stays visible
LOCKED_RGB = (1.0, 0.1, 0.1)  # the controller's target in red, as on the image (convert.py)
LABEL_FONT_PX = 14.0
#: The base frame's axes seen from the optical frame: x right = -y, y down = -z, z forward = x.
#: As a quaternion (x, y, z, w): a level camera looking along the base's x.
OPTICAL = (-0.5, 0.5, -0.5, 0.5)


def optical_frames(cameras: Mapping[str, CameraAnnouncement]) -> dict[str, str]:
    """The frame each camera's 3D boxes are in: the frame id its source announces (its images
    carry it), else (none, or one that another camera announces too: cameras left at the
    default ``camera``) ``<camera>_optical``, so that no two cameras share a frame."""
    ids = Counter(a.frame_id for a in cameras.values())
    return {
        name: a.frame_id if a.frame_id and ids[a.frame_id] == 1 else f"{name}_optical"
        for name, a in cameras.items()
    }


def depth_image(frame: DepthFrame, max_width: int) -> RawImage:
    """``frame`` as a 16UC1 (mm) ``RawImage`` no wider than ``max_width`` (0: its own width).
    Scaled by nearest neighbour: every pixel sent is a reading, never a blend of the near and
    far sides of an edge. No reading (and a 32FC1 image's NaN, inf, out of range) is 0."""
    metres = depth_metres(frame)
    mm = np.nan_to_num(np.round(metres * 1000.0), nan=0.0)
    pixels = np.clip(mm, 0, MAX_DEPTH_MM).astype("<u2")
    size = scaled_size(frame.width, frame.height, max_width)
    if size != (frame.width, frame.height):
        pixels = cv2.resize(pixels, size, interpolation=cv2.INTER_NEAREST)
    width, height = size
    return RawImage(
        timestamp=stamp(frame.header.stamp_ns),
        frame_id=frame.header.frame_id,
        width=width,
        height=height,
        encoding=DEPTH_ENCODING,
        step=width * 2,
        data=np.ascontiguousarray(pixels).tobytes(),
    )


def has_depth(dets: Detections) -> bool:
    """Whether the detector measured these detections' depth (every depth column present)."""
    return all(name in dets.boxes.columns for name in COLUMNS)


def _multiply(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def mount_rotation(yaw_deg: float) -> Quaternion:
    """The rotation from ``base_link`` to a level optical frame turned ``yaw_deg``
    counter-clockwise: the yaw about the base's z, then the optical axes."""
    half = math.radians(yaw_deg) / 2
    x, y, z, w = _multiply((0.0, 0.0, math.sin(half), math.cos(half)), OPTICAL)
    return Quaternion(x=x, y=y, z=z, w=w)


def camera_transforms(cameras: Mapping[str, CameraAnnouncement], stamp_ns: int) -> FrameTransforms:
    """``base_link`` -> each announced camera's optical frame, by its mounting (a camera of
    unknown height, 0, is drawn on the floor)."""
    ts = stamp(stamp_ns)
    frames = optical_frames(cameras)
    mounts = {name: Mounting.of(a) for name, a in cameras.items()}
    return FrameTransforms(
        transforms=[
            FrameTransform(
                timestamp=ts,
                parent_frame_id=ROBOT_FRAME,
                child_frame_id=frames[name],
                translation=Vector3(x=m.x_m, y=m.y_m, z=m.height_m),
                rotation=mount_rotation(m.yaw_deg),
            )
            for name, m in mounts.items()
        ]
    )


def _colour(class_id: int, locked: bool, alpha: float) -> Color:
    """A box's colour: its class's, as the 2D boxes (common/annotate.py), or the target's."""
    if locked:
        r, g, b = LOCKED_RGB
    else:
        bc, gc, rc = class_colour(class_id)
        r, g, b = rc / 255, gc / 255, bc / 255
    return Color(r=r, g=g, b=b, a=alpha)


def _known(columns: Mapping[str, npt.NDArray[np.float32]], n: int) -> npt.NDArray[np.bool_]:
    """The rows whose centre and extent are all finite (NaN: depth unknown, no cube)."""
    known = np.ones(n, bool)
    for name in (*CENTRE, *SIZE):
        known &= np.isfinite(columns[name])
    return known


def boxes_scene(
    dets: Detections, camera: str, frame_id: str, locked_track: int, lifetime_s: float
) -> SceneUpdate:
    """``camera``'s detections with depth (:func:`has_depth`) as one entity of cubes in its
    optical frame ``frame_id``, each labelled with its class and distance; the controller's
    target (``locked_track``) in red. The entity (id ``boxes/<camera>``) replaces the camera's
    previous one and lasts ``lifetime_s``: a camera whose detections stop loses its boxes.
    A row of unknown depth (NaN) has no cube."""
    cols = dets.boxes.columns
    n = len(dets)
    known = _known(cols, n)
    tracks = dets.boxes.track_ids.tolist() if dets.boxes.track_ids is not None else [-1] * n
    cubes: list[CubePrimitive] = []
    texts: list[TextPrimitive] = []
    level = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)  # axis-aligned in the optical frame
    for i in np.flatnonzero(known).tolist():
        x, y, z = (float(cols[c][i]) for c in CENTRE)
        sx, sy, sz = (max(0.0, float(cols[c][i])) for c in SIZE)
        locked = tracks[i] >= 0 and tracks[i] == locked_track
        cid = int(dets.boxes.class_ids[i])
        cubes.append(
            CubePrimitive(
                pose=Pose(position=Vector3(x=x, y=y, z=z), orientation=level),
                size=Vector3(x=sx, y=sy, z=sz),
                color=_colour(cid, locked, BOX_ALPHA),
            )
        )
        distance = float(cols[DISTANCE][i])
        said = f"{distance:.2f} m" if math.isfinite(distance) else "? m"
        texts.append(
            TextPrimitive(
                pose=Pose(position=Vector3(x=x, y=y - sy / 2, z=z), orientation=level),  # on top
                billboard=True,
                font_size=LABEL_FONT_PX,
                scale_invariant=True,
                color=_colour(cid, locked, 1.0),
                text=("LOCKED " if locked else "") + f"{dets.class_names[i]} {said}",
            )
        )
    sec, frac = divmod(lifetime_s, 1.0)
    entity = SceneEntity(
        timestamp=stamp(dets.header.stamp_ns),
        frame_id=frame_id,
        id=f"boxes/{camera}",
        lifetime=Duration(int(sec), int(frac * 1e9)),
        frame_locked=True,  # drawn where the camera is now: it moves with the robot
        cubes=cubes,
        texts=texts,
    )
    return SceneUpdate(entities=[entity])
