"""Depth to and from ROS: ``sensor_msgs/Image`` (16UC1, 32FC1) with its ``CameraInfo`` in as a
DepthFrame (and a DepthFrame out as the two, as a depth camera's driver sends them: the
simulator playing a ROS 2 robot), and the detections' depth columns out as
``vision_msgs/Detection3DArray``. No I/O.

Bad input raises ``DecodeError`` and nothing else; rosmsg/convert.py has the header
conventions and the CDR helpers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.errors import DecodeError
from common.messages import DEPTH_ENCODINGS, DepthFrame, Detections
from perception import DEPTH_CENTRE, DEPTH_SIZE, Mounting, to_robot
from rosmsg.convert import RosMessage, build, header_from_ros, ros_header
from rosmsg.distro import RosDistro
from rosmsg.images import raw_image
from rosmsg.typestore import typestore_for

CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
DETECTION_3D_ARRAY = "vision_msgs/msg/Detection3DArray"


@dataclass(frozen=True, slots=True)
class DepthIntrinsics:
    """What a DepthFrame takes from a ``CameraInfo``: the pinhole focal lengths and principal
    point, in pixels of a ``width`` x ``height`` image (binning and region of interest applied)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int


def intrinsics_from_camera_info(msg: RosMessage) -> DepthIntrinsics:
    """fx, fy, cx, cy from ``k`` (row-major 3x3), for the images the camera sends: ROS states
    ``k`` for the full sensor, so a region of interest moves the principal point and binning
    divides everything. DecodeError for an uncalibrated (``k`` all zero) or absurd one."""
    try:
        k = [float(v) for v in msg.k]
        width, height = int(msg.width), int(msg.height)
        bx, by = max(1, int(msg.binning_x)), max(1, int(msg.binning_y))
        roi = msg.roi
        ox, oy = int(roi.x_offset), int(roi.y_offset)
        if int(roi.width) and int(roi.height):
            width, height = int(roi.width), int(roi.height)
    except (TypeError, ValueError, AttributeError) as exc:
        raise DecodeError(f"CameraInfo: {exc}") from exc
    if len(k) != 9:
        raise DecodeError(f"CameraInfo: k has {len(k)} values, not 9")
    fx, cx, fy, cy = k[0], k[2], k[4], k[5]
    if not all(math.isfinite(v) for v in (fx, fy, cx, cy)) or fx <= 0 or fy <= 0:
        raise DecodeError(f"CameraInfo: no usable intrinsics in k {k} (uncalibrated?)")
    return DepthIntrinsics(
        fx=fx / bx,
        fy=fy / by,
        cx=(cx - ox) / bx,
        cy=(cy - oy) / by,
        width=width // bx,
        height=height // by,
    )


def depth_encoding(msg: RosMessage) -> str | None:
    """The image's encoding when a DepthFrame can carry it (16UC1, 32FC1), else None."""
    encoding = str(msg.encoding)
    return encoding if encoding in DEPTH_ENCODINGS else None


def depth_from_image(
    msg: RosMessage, intr: DepthIntrinsics, *, source: str, seq: int = 0
) -> DepthFrame:
    """A 16UC1 (mm) or 32FC1 (m) ``sensor_msgs/Image`` as a DepthFrame with ``intr``; the
    header is the image's, as colour frames get theirs (rosmsg/images.py), so the
    detector pairs the two by stamp. The pixels are copied little-endian without row padding.

    The caller has checked the encoding (:func:`depth_encoding`) and that the image is
    ``intr``'s size; DecodeError for anything else wrong with it."""
    encoding = str(msg.encoding)
    size = DEPTH_ENCODINGS.get(encoding, 0)
    if not size:
        raise DecodeError(f"depth Image: unsupported encoding {encoding!r} (16UC1, 32FC1)")
    width, height, step = int(msg.width), int(msg.height), int(msg.step)
    data = msg.data
    row = width * size
    if width <= 0 or height <= 0 or step < row or len(data) != step * height:
        raise DecodeError(
            f"depth Image: {encoding} {width}x{height} with step {step} needs step >= {row} and "
            f"step*height bytes, got {len(data)}"
        )
    rows = np.asarray(data, np.uint8).reshape(height, step)[:, :row]
    order = ">" if int(msg.is_bigendian) else "<"
    kind = "u2" if encoding == "16UC1" else "f4"
    pixels = np.ascontiguousarray(rows).view(f"{order}{kind}").astype(f"<{kind}", copy=False)
    header = header_from_ros(msg.header, source=source, seq=seq)
    try:
        return DepthFrame(
            header=header, encoding=encoding, width=width, height=height,
            data=pixels.tobytes(), fx=intr.fx, fy=intr.fy, cx=intr.cx, cy=intr.cy,
        )  # fmt: skip
    except ValueError as exc:
        raise DecodeError(f"depth Image: {exc}") from exc


def depth_to_image(distro: RosDistro, frame: DepthFrame) -> RosMessage:
    """A DepthFrame as the ``sensor_msgs/Image`` a depth camera's driver sends: its encoding
    (16UC1 mm, 32FC1 m), little-endian rows unpadded, its header's stamp and frame id (those of
    the colour frame it is aligned to). The pixels are not copied."""
    return raw_image(distro, frame.header, frame.encoding, frame.width, frame.height,
                     DEPTH_ENCODINGS[frame.encoding], frame.data)  # fmt: skip


def camera_info_of(distro: RosDistro, frame: DepthFrame) -> RosMessage:
    """The ``sensor_msgs/CameraInfo`` of a DepthFrame's image: its size and pinhole intrinsics
    (``k``, and ``p`` for a rectified image), no distortion, under the frame's header. What
    :func:`intrinsics_from_camera_info` reads back."""
    fx, fy, cx, cy = frame.fx, frame.fy, frame.cx, frame.cy
    roi = build(
        distro,
        "sensor_msgs/msg/RegionOfInterest",
        x_offset=0,
        y_offset=0,
        height=0,
        width=0,
        do_rectify=False,
    )
    return build(
        distro,
        CAMERA_INFO,
        header=ros_header(distro, frame.header.stamp_ns, frame.header.frame_id),
        height=frame.height,
        width=frame.width,
        distortion_model="plumb_bob",
        d=np.zeros(5, np.float64),
        k=np.array([fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0], np.float64),
        r=np.eye(3, dtype=np.float64).ravel(),
        p=np.array([fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0], np.float64),
        binning_x=0,
        binning_y=0,
        roi=roi,
    )


def has_3d(dets: Detections) -> bool:
    """Whether ``dets`` carry the depth stage's 3D centre and size columns."""
    return all(name in dets.boxes.columns for name in (*DEPTH_CENTRE, *DEPTH_SIZE))


def detections_3d_to_ros(
    distro: RosDistro,
    dets: Detections,
    *,
    frame_id: str = "",
    mount: Mounting | None = None,
) -> tuple[RosMessage, int]:
    """The detections with a known 3D centre and size as a ``vision_msgs/Detection3DArray``,
    and how many were left out for an unknown one (NaN). Call it only when :func:`has_3d`.

    Without ``mount``: in the detections' frame (the camera's optical frame: x right, y down,
    z forward), the box's orientation identity, its size (size_x_m, size_y_m, size_z_m). With
    ``mount`` (the camera's announced mounting): in ``frame_id``, the robot's base frame
    (x forward, y left, z up; perception.depth.to_robot), the box turned by the camera's yaw
    and its size along (forward, left, up) = (size_z_m, size_x_m, size_y_m). One hypothesis
    per detection (class name, score) whose pose is the box's centre; ``id`` the track id, ""
    without one.
    """
    types = typestore_for(distro).types
    cols = dets.boxes.columns
    x, y, z = (np.asarray(cols[name], np.float32) for name in DEPTH_CENTRE)
    sx, sy, sz = (np.asarray(cols[name], np.float64) for name in DEPTH_SIZE)
    known = np.isfinite(np.stack([x, y, z, sx, sy, sz])).all(axis=0)
    if mount is None:
        frame = dets.header.frame_id
        px, py, pz = x.astype(np.float64), y.astype(np.float64), z.astype(np.float64)
        size = (sx, sy, sz)
        quaternion = (0.0, 0.0, 0.0, 1.0)
    else:
        frame = frame_id
        px, py, pz = to_robot(x, y, z, mount)
        size = (sz, sx, sy)
        half_yaw = math.radians(mount.yaw_deg) / 2
        quaternion = (0.0, 0.0, math.sin(half_yaw), math.cos(half_yaw))
    header = ros_header(distro, dets.header.stamp_ns, frame)
    point, vector3 = types["geometry_msgs/msg/Point"], types["geometry_msgs/msg/Vector3"]
    pose_type, quat = types["geometry_msgs/msg/Pose"], types["geometry_msgs/msg/Quaternion"]
    orientation = quat(*quaternion)
    with_cov = types["geometry_msgs/msg/PoseWithCovariance"]
    hypothesis_with_pose = types["vision_msgs/msg/ObjectHypothesisWithPose"]
    hypothesis = types["vision_msgs/msg/ObjectHypothesis"]
    detection3d = types["vision_msgs/msg/Detection3D"]
    bbox3d = types["vision_msgs/msg/BoundingBox3D"]
    boxes = dets.boxes
    tracks = [-1] * len(dets) if boxes.track_ids is None else boxes.track_ids.tolist()
    scores = boxes.scores.astype(np.float64).tolist()
    detections = []
    for i in np.flatnonzero(known).tolist():
        pose = pose_type(position=point(float(px[i]), float(py[i]), float(pz[i])),
                         orientation=orientation)  # fmt: skip
        result = hypothesis_with_pose(
            hypothesis=hypothesis(class_id=dets.class_names[i], score=scores[i]),
            pose=with_cov(pose=pose, covariance=np.zeros(36, np.float64)),
        )
        extent = vector3(float(size[0][i]), float(size[1][i]), float(size[2][i]))
        detections.append(
            detection3d(
                header=header,
                results=[result],
                bbox=bbox3d(center=pose, size=extent),
                id="" if tracks[i] < 0 else str(tracks[i]),
            )
        )
    unknown = len(dets) - len(detections)
    return types[DETECTION_3D_ARRAY](header=header, detections=detections), unknown
