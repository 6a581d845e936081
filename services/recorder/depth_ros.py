"""A camera's depth images in a recording: DepthFrame -> ``sensor_msgs/Image`` (16UC1 or 32FC1,
as ROS depth drivers publish them) and its ``sensor_msgs/CameraInfo``, and back (the bridge's
translation, rosmsg/depth.py). No I/O.

Each DepthFrame is two ROS messages, as a ROS depth camera publishes it and the bridge takes it
in: the image on the camera's ``ros2.depth_topic`` and its intrinsics on
``ros2.depth_info_topic`` (a further camera's under ``ros2.camera_namespace``), so that Foxglove
shows the depth image (and projects it with its CameraInfo) and a ROS 2 bag of a RealSense or
OAK (``aligned_depth_to_color/image_raw`` and its ``camera_info``) plays back as depth too.

A CameraInfo cannot carry the sensor's valid range: the recorder puts it in the depth image
channel's metadata (``range_min_m``, ``range_max_m``; channels.py), a bag from elsewhere has
none (0: not stated).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from common.errors import DecodeError
from common.messages import DEPTH_ENCODINGS, DepthFrame
from rosmsg.convert import RosMessage
from rosmsg.depth import CAMERA_INFO, depth_from_image, intrinsics_from_camera_info
from rosmsg.distro import RosDistro
from rosmsg.images import IMAGE
from rosmsg.typestore import typestore_for
from services.ros2.contract import Ros2Settings, camera_topics

#: The name of the intrinsics topic beside a depth image topic (ROS's image_transport): a bag's
#: depth topic that is no configured camera's has its CameraInfo there.
INFO_NAME = "camera_info"
#: Channel metadata of a depth image channel: the sensor's valid range, metres.
RANGE_MIN, RANGE_MAX = "range_min_m", "range_max_m"


@dataclass(frozen=True, slots=True)
class DepthTopics:
    image: str
    info: str


def depth_topics(ros2: Ros2Settings, first: str, camera: str) -> DepthTopics:
    """``camera``'s depth image and CameraInfo topics (``first``: stack.camera), the bridge's."""
    topics = camera_topics(ros2, first, camera)
    return DepthTopics(topics.depth, topics.depth_info)


def sibling_info_topic(image_topic: str) -> str:
    """The CameraInfo topic beside an image topic: ``/a/b/image_raw`` -> ``/a/b/camera_info``."""
    parent, _, _ = image_topic.rstrip("/").rpartition("/")
    return f"{parent}/{INFO_NAME}"


def is_depth_topic(topic: str, known: Iterable[str] = ()) -> bool:
    """Whether an image topic carries depth: one of ``known`` (the configured cameras' depth
    topics), or by its name, as the drivers name theirs (``.../depth/image_raw``,
    ``.../aligned_depth_to_color/image_raw``, ``.../depth_registered/...``)."""
    return topic in known or "depth" in topic.lower()


def _build(distro: RosDistro, ros_type: str, **fields: Any) -> RosMessage:
    return typestore_for(distro).types[ros_type](**fields)


def _ros_header(distro: RosDistro, stamp_ns: int, frame_id: str) -> RosMessage:
    """A ``std_msgs/Header``; ValueError for a stamp a ROS Time (int32 seconds) cannot hold."""
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    if not 0 <= sec < 2**31:
        raise ValueError(f"stamp {stamp_ns} ns does not fit a ROS Time")
    stamp = _build(distro, "builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)
    return _build(distro, "std_msgs/msg/Header", stamp=stamp, frame_id=frame_id)


def depth_to_ros(distro: RosDistro, depth: DepthFrame) -> tuple[RosMessage, RosMessage]:
    """``depth`` as (CameraInfo, Image): plumb_bob with no distortion (the source rectifies),
    ``k`` and ``p`` from its pinhole intrinsics; the pixels are not copied."""
    header = _ros_header(distro, depth.header.stamp_ns, depth.header.frame_id)
    fx, fy, cx, cy = depth.fx, depth.fy, depth.cx, depth.cy
    info = _build(
        distro, CAMERA_INFO, header=header, height=depth.height, width=depth.width,
        distortion_model="plumb_bob", d=np.zeros(5, np.float64),
        k=np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], np.float64),
        r=np.eye(3, dtype=np.float64).reshape(9),
        p=np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], np.float64),
        binning_x=0, binning_y=0,
        roi=_build(distro, "sensor_msgs/msg/RegionOfInterest", x_offset=0, y_offset=0, height=0,
                  width=0, do_rectify=False),
    )  # fmt: skip
    image = _build(
        distro, IMAGE, header=header, height=depth.height, width=depth.width,
        encoding=depth.encoding, is_bigendian=0,
        step=depth.width * DEPTH_ENCODINGS[depth.encoding],
        data=np.frombuffer(depth.data, dtype=np.uint8),
    )  # fmt: skip
    return info, image


def depth_from_ros(
    image: RosMessage,
    info: RosMessage,
    *,
    source: str,
    seq: int,
    range_m: tuple[float, float] = (0.0, 0.0),
) -> DepthFrame:
    """A depth ``sensor_msgs/Image`` (16UC1 mm or 32FC1 m) with the intrinsics of its
    CameraInfo as a DepthFrame (``range_m``: min, max; 0 for not stated), as the bridge takes
    one in. DecodeError for anything else, and for a CameraInfo of another size than the
    image."""
    intr = intrinsics_from_camera_info(info)
    if (int(image.width), int(image.height)) != (intr.width, intr.height):
        raise DecodeError(
            f"depth Image: {image.width}x{image.height}, its CameraInfo {intr.width}x{intr.height}"
        )
    frame = depth_from_image(image, intr, source=source, seq=seq)
    try:
        return dataclasses.replace(frame, range_min_m=range_m[0], range_max_m=range_m[1])
    except ValueError as exc:
        raise DecodeError(f"depth Image: {exc}") from exc
