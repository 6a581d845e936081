"""A camera's depth images in a recording: DepthFrame <-> ``sensor_msgs/Image`` (16UC1 or 32FC1,
as ROS depth drivers publish them) and its ``sensor_msgs/CameraInfo``. No I/O.

Each DepthFrame is two ROS messages, as a ROS depth camera publishes it: the image on the
camera's depth topic and its intrinsics on the ``camera_info`` topic beside it (the ROS
convention: ``/camera/depth/image_raw`` and ``/camera/depth/camera_info``), so that Foxglove
shows the depth image (and projects it with its CameraInfo) and a ROS 2 bag of a RealSense or
OAK (``aligned_depth_to_color/image_raw`` and its ``camera_info``) plays back as depth too.

A CameraInfo cannot carry the sensor's valid range: the recorder puts it in the depth image
channel's metadata (``range_min_m``, ``range_max_m``; channels.py), a bag from elsewhere has
none (0: not stated).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from common.errors import DecodeError
from common.messages import DEPTH_ENCODINGS, DepthFrame, Header
from services.ros2 import IMAGE, RosDistro, RosMessage, typestore_for
from services.ros2.contract import Ros2Settings, camera_topics

CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
#: The first camera's depth topic (stack.camera); a further camera's is under
#: ``ros2.camera_namespace`` (``/rear/camera/depth/image_raw``), as its image topic is.
DEPTH_IMAGE_TOPIC = "/camera/depth/image_raw"
#: The name of the intrinsics topic beside a depth image topic (ROS's image_transport).
INFO_NAME = "camera_info"
#: Channel metadata of a depth image channel: the sensor's valid range, metres.
RANGE_MIN, RANGE_MAX = "range_min_m", "range_max_m"


@dataclass(frozen=True, slots=True)
class DepthTopics:
    image: str
    info: str


def info_topic(image_topic: str) -> str:
    """The CameraInfo topic beside an image topic: ``/a/b/image_raw`` -> ``/a/b/camera_info``."""
    parent, _, _ = image_topic.rstrip("/").rpartition("/")
    return f"{parent}/{INFO_NAME}"


def depth_topics(ros2: Ros2Settings, first: str, camera: str) -> DepthTopics:
    """``camera``'s depth image and CameraInfo topics (``first``: stack.camera)."""
    image = camera_topics(dataclasses.replace(ros2, image_topic=DEPTH_IMAGE_TOPIC), first, camera)
    return DepthTopics(image.image, info_topic(image.image))


def is_depth_topic(topic: str) -> bool:
    """Whether an image topic carries depth, by its name: ours (``.../depth/image_raw``) and
    the drivers' (``.../aligned_depth_to_color/image_raw``, ``.../depth_registered/...``)."""
    return "depth" in topic.lower()


def _build(distro: RosDistro, ros_type: str, **fields: Any) -> RosMessage:
    return typestore_for(distro).types[ros_type](**fields)


def _ros_header(distro: RosDistro, stamp_ns: int, frame_id: str) -> RosMessage:
    """A ``std_msgs/Header``; ValueError for a stamp a ROS Time (int32 seconds) cannot hold."""
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    if not 0 <= sec < 2**31:
        raise ValueError(f"stamp {stamp_ns} ns does not fit a ROS Time")
    stamp = _build(distro, "builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)
    return _build(distro, "std_msgs/msg/Header", stamp=stamp, frame_id=frame_id)


def _header(ros: RosMessage, *, source: str, seq: int) -> Header:
    """The stack's header of a ROS one (its stamp the capture stamp; no clock of ours)."""
    sec, nanosec = int(ros.stamp.sec), int(ros.stamp.nanosec)
    if sec < 0 or not 0 <= nanosec < 1_000_000_000:
        raise DecodeError(f"invalid ROS stamp {sec}s {nanosec}ns")
    return Header(stamp_ns=sec * 1_000_000_000 + nanosec, frame_id=str(ros.frame_id), seq=seq,
                  source=source, mono_ns=0, boot_id="")  # fmt: skip


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


def intrinsics_from_ros(info: RosMessage) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) of a CameraInfo's ``k``; DecodeError when it has none."""
    k = np.asarray(info.k, dtype=np.float64)
    if k.shape != (9,) or not np.isfinite(k).all() or k[0] <= 0 or k[4] <= 0:
        raise DecodeError(f"CameraInfo: no pinhole intrinsics in k {k.tolist()}")
    return float(k[0]), float(k[4]), float(k[2]), float(k[5])


def depth_from_ros(
    image: RosMessage,
    info: RosMessage,
    *,
    source: str,
    seq: int,
    range_m: tuple[float, float] = (0.0, 0.0),
) -> DepthFrame:
    """A depth ``sensor_msgs/Image`` (16UC1 mm or 32FC1 m, little-endian) with the intrinsics
    of its CameraInfo as a DepthFrame (``range_m``: min, max; 0 for not stated). The
    intrinsics are scaled when the CameraInfo is for another size than the image. DecodeError
    for anything else."""
    encoding = str(image.encoding)
    size = DEPTH_ENCODINGS.get(encoding)
    if size is None:
        raise DecodeError(f"depth Image: unsupported encoding {encoding!r} (16UC1 or 32FC1)")
    if int(image.is_bigendian):
        raise DecodeError("depth Image: big-endian pixels are not supported")
    width, height, step = int(image.width), int(image.height), int(image.step)
    data = image.data
    row = width * size
    if step < row or len(data) != step * height:
        raise DecodeError(
            f"depth Image: {encoding} {width}x{height} with step {step} needs step >= {row} "
            f"and step*height bytes, got {len(data)}"
        )
    if step != row and height:
        data = data.reshape(height, step)[:, :row]
    fx, fy, cx, cy = intrinsics_from_ros(info)
    info_w, info_h = int(info.width), int(info.height)
    if info_w > 0 and info_h > 0 and (info_w, info_h) != (width, height):
        sx, sy = width / info_w, height / info_h
        fx, cx, fy, cy = fx * sx, cx * sx, fy * sy, cy * sy
    try:
        return DepthFrame(
            header=_header(image.header, source=source, seq=seq),
            encoding=encoding, width=width, height=height, data=data.tobytes(),
            fx=fx, fy=fy, cx=cx, cy=cy, range_min_m=range_m[0], range_max_m=range_m[1],
        )  # fmt: skip
    except ValueError as exc:
        raise DecodeError(f"depth Image: {exc}") from exc
