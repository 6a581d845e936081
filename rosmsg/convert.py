"""Translations between the stack's messages and ROS 2 messages, and CDR in and out. No I/O.

ROS messages are rosbags' generated dataclasses (typed here as ``RosMessage``): one class per
type per distribution, so every function that builds one takes the ``RosDistro``. Payloads are
CDR as rmw_zenoh carries them; bad input raises ``DecodeError`` and nothing else.

A ROS header has no sequence number, no producer and only a wall-clock stamp: the stack's
header built from one gets ``seq`` and ``source`` from the caller (the attachment's sequence
number, the bridge's name) and ``mono_ns=0, boot_id=""`` (unknown).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from common.errors import DecodeError, one_line
from common.messages import Detections, Header, LaserScan, Twist
from rosmsg.distro import RosDistro
from rosmsg.typestore import typestore_for

#: A rosbags message instance; its class is generated per type and distribution at run time.
RosMessage = Any

LASER_SCAN = "sensor_msgs/msg/LaserScan"
TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
DETECTION_2D_ARRAY = "vision_msgs/msg/Detection2DArray"

DEFAULT_BASE_FRAME = "base_link"
_NS_PER_S = 1_000_000_000
_INT32_MAX = 2**31 - 1


def cdr_encode(distro: RosDistro, ros_type: str, msg: RosMessage) -> bytes:
    """``msg`` as little-endian CDR with its encapsulation header, as rmw_zenoh puts it."""
    return bytes(typestore_for(distro).serialize_cdr(msg, ros_type, little_endian=True))


def cdr_decode(
    distro: RosDistro, ros_type: str, payload: bytes | bytearray | memoryview
) -> RosMessage:
    """The ROS message in ``payload``; DecodeError for anything that is not one.

    Arrays of the result (an image's pixels) are views into ``payload``, not copies.
    """
    store = typestore_for(distro)
    if ros_type not in store.types:
        raise ValueError(f"{ros_type} is not a known {distro} type")
    try:
        # A memoryview, so that rosbags' slicing past the encapsulation header copies nothing.
        return store.deserialize_cdr(memoryview(payload), ros_type)
    except Exception as exc:  # rosbags raises SerdeError, but garbage can reach other errors
        raise DecodeError(f"{ros_type}: not valid CDR ({one_line(exc)})") from exc


def build(distro: RosDistro, ros_type: str, **fields: Any) -> RosMessage:
    """A new ``ros_type`` message of ``distro`` with ``fields``."""
    return typestore_for(distro).types[ros_type](**fields)


# ---------------------------------------------------------------------------- headers


def stamp_ns_from_ros(stamp: RosMessage) -> int:
    """A ``builtin_interfaces/Time`` as ns since the epoch; DecodeError for an impossible one."""
    sec, nanosec = int(stamp.sec), int(stamp.nanosec)
    if sec < 0 or not 0 <= nanosec < _NS_PER_S:
        raise DecodeError(f"invalid ROS stamp {sec}s {nanosec}ns")
    return sec * _NS_PER_S + nanosec


def ros_time(distro: RosDistro, stamp_ns: int) -> RosMessage:
    """ns since the epoch as a ``builtin_interfaces/Time`` (int32 seconds: until 2038)."""
    sec, nanosec = divmod(stamp_ns, _NS_PER_S)
    if not 0 <= sec <= _INT32_MAX:
        raise ValueError(f"stamp {stamp_ns} ns does not fit a ROS Time")
    return build(distro, "builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)


def ros_header(distro: RosDistro, stamp_ns: int, frame_id: str) -> RosMessage:
    return build(distro, "std_msgs/msg/Header", stamp=ros_time(distro, stamp_ns), frame_id=frame_id)


def header_from_ros(header: RosMessage, *, source: str, seq: int = 0) -> Header:
    """The stack's header for a ROS one: the stamp becomes the capture stamp ``stamp_ns``."""
    return Header(
        stamp_ns=stamp_ns_from_ros(header.stamp),
        frame_id=str(header.frame_id),
        seq=seq,
        source=source,
        mono_ns=0,
        boot_id="",
    )


# ---------------------------------------------------------------------------- scans


def scan_from_ros(msg: RosMessage, *, source: str, seq: int = 0) -> LaserScan:
    """A ``sensor_msgs/LaserScan`` as the stack's; intensities and timing are dropped."""
    header = header_from_ros(msg.header, source=source, seq=seq)
    try:
        return LaserScan(
            header=header,
            angle_min=float(msg.angle_min),
            angle_increment=float(msg.angle_increment),
            range_min=float(msg.range_min),
            range_max=float(msg.range_max),
            # A copy in native order: the payload may be big-endian, and it is not ours to keep.
            ranges=np.array(msg.ranges, dtype=np.float32),
        )
    except ValueError as exc:
        raise DecodeError(f"LaserScan: {exc}") from exc


def scan_to_ros(distro: RosDistro, scan: LaserScan) -> RosMessage:
    """The stack's scan as a ``sensor_msgs/LaserScan`` (no intensities, timing unknown: 0)."""
    n = len(scan.ranges)
    return build(
        distro,
        LASER_SCAN,
        header=ros_header(distro, scan.header.stamp_ns, scan.header.frame_id),
        angle_min=scan.angle_min,
        angle_max=scan.angle_min + (n - 1) * scan.angle_increment,
        angle_increment=scan.angle_increment,
        time_increment=0.0,
        scan_time=0.0,
        range_min=scan.range_min,
        range_max=scan.range_max,
        ranges=np.ascontiguousarray(scan.ranges, dtype=np.float32),
        intensities=np.zeros(0, dtype=np.float32),
    )


# ---------------------------------------------------------------------------- detections


def detections_to_ros(distro: RosDistro, dets: Detections) -> RosMessage:
    """The stack's detections as a ``vision_msgs/Detection2DArray``.

    One hypothesis per detection (class name, score); the box as centre and size in pixels;
    ``id`` the track id, "" without one. Every Detection2D carries the array's header (the
    frame's). The pose is unknown: identity, zero covariance. The boxes' named columns
    (``distance_m`` ...) have no slot in vision_msgs and are left out (docs/ros2.md): the
    recorder's JSON channel and the viewer's labels carry them.
    """
    types = typestore_for(distro).types
    header = ros_header(distro, dets.header.stamp_ns, dets.header.frame_id)
    # rosbags only reads a message to serialize it, so one unknown pose serves every detection.
    pose = types["geometry_msgs/msg/PoseWithCovariance"](
        pose=types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
            orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        ),
        covariance=np.zeros(36, dtype=np.float64),
    )
    boxes = dets.boxes
    xyxy = boxes.xyxy.astype(np.float64)
    centers = ((xyxy[:, :2] + xyxy[:, 2:]) / 2).tolist()
    sizes = (xyxy[:, 2:] - xyxy[:, :2]).tolist()
    scores = boxes.scores.astype(np.float64).tolist()
    tracks = [-1] * len(dets) if boxes.track_ids is None else boxes.track_ids.tolist()
    detection2d = types["vision_msgs/msg/Detection2D"]
    hypothesis_with_pose = types["vision_msgs/msg/ObjectHypothesisWithPose"]
    hypothesis = types["vision_msgs/msg/ObjectHypothesis"]
    bbox, pose2d = types["vision_msgs/msg/BoundingBox2D"], types["vision_msgs/msg/Pose2D"]
    point2d = types["vision_msgs/msg/Point2D"]
    detections = [
        detection2d(
            header=header,
            results=[
                hypothesis_with_pose(hypothesis=hypothesis(class_id=name, score=score), pose=pose)
            ],
            bbox=bbox(center=pose2d(position=point2d(x=cx, y=cy), theta=0.0), size_x=w, size_y=h),
            id="" if track < 0 else str(track),
        )
        for name, score, (cx, cy), (w, h), track in zip(
            dets.class_names, scores, centers, sizes, tracks, strict=True
        )
    ]
    return types[DETECTION_2D_ARRAY](header=header, detections=detections)


# ---------------------------------------------------------------------------- twists


def twist_to_ros(
    distro: RosDistro, twist: Twist, *, stamped: bool = False, frame_id: str = DEFAULT_BASE_FRAME
) -> RosMessage:
    """A ``geometry_msgs/Twist``, or with ``stamped`` a ``TwistStamped`` whose stamp is the
    command's header stamp, in ``frame_id``."""
    vector3 = typestore_for(distro).types["geometry_msgs/msg/Vector3"]
    linear, angular = (float(v) for v in twist.linear), (float(v) for v in twist.angular)
    ros_twist = build(distro, TWIST, linear=vector3(*linear), angular=vector3(*angular))
    if not stamped:
        return ros_twist
    header = ros_header(distro, twist.header.stamp_ns, frame_id)
    return build(distro, TWIST_STAMPED, header=header, twist=ros_twist)


def twist_from_ros(msg: RosMessage, *, source: str, received_ns: int, seq: int = 0) -> Twist:
    """A ``geometry_msgs/Twist`` or ``TwistStamped`` as the stack's Twist.

    A bare Twist has no stamp or frame: it is stamped ``received_ns`` in ``base_link``.
    Non-finite or absurd velocities raise DecodeError: they must never reach a motor.
    """
    if msg.__msgtype__ == TWIST_STAMPED:
        header = header_from_ros(msg.header, source=source, seq=seq)
        msg = msg.twist
    else:
        header = Header(stamp_ns=received_ns, frame_id=DEFAULT_BASE_FRAME, seq=seq, source=source)
    linear = (float(msg.linear.x), float(msg.linear.y), float(msg.linear.z))
    angular = (float(msg.angular.x), float(msg.angular.y), float(msg.angular.z))
    if not all(math.isfinite(v) for v in (*linear, *angular)):
        raise DecodeError(f"Twist: velocities must be finite, got {linear} {angular}")
    try:
        return Twist(header=header, linear=linear, angular=angular)
    except ValueError as exc:  # beyond what any base takes (common.messages.MAX_COMMAND)
        raise DecodeError(f"Twist: {exc}") from exc
