"""Depth in (a depth sensor_msgs/Image with its CameraInfo -> DepthFrame) and 3D detections out
(Detections with depth columns -> vision_msgs/Detection3DArray), through CDR written and read by
rosbags with the very type definitions the bridge uses. The bridge's handlers over these:
tests/unit/ros2/test_depth_handlers.py."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from common.boxes import Boxes
from common.errors import DecodeError
from common.messages import DepthFrame, Detections, Header
from perception.depth import COLUMNS, Mounting, depth_metres, to_robot
from rosmsg.convert import build, cdr_decode, cdr_encode, ros_header
from rosmsg.depth import (
    CAMERA_INFO,
    DETECTION_3D_ARRAY,
    DepthIntrinsics,
    depth_from_image,
    detections_3d_to_ros,
    has_3d,
    intrinsics_from_camera_info,
)
from rosmsg.distro import RosDistro
from rosmsg.images import IMAGE
from rosmsg.typestore import typestore_for

STAMP_NS = 1_700_000_000_250_000_000
DISTROS = [RosDistro.HUMBLE, RosDistro.JAZZY, RosDistro.KILTED, RosDistro.ROLLING]
W, H = 8, 6
MM = np.arange(W * H, dtype=np.uint16).reshape(H, W) * 100 + 500  # 0.5 m .. 5.2 m


def camera_info(distro: RosDistro, **changes: Any) -> bytes:
    k = np.array([400.0, 0, 4.5, 0, 410.0, 3.25, 0, 0, 1], np.float64)
    types = typestore_for(distro).types
    fields: dict[str, Any] = {
        "header": ros_header(distro, STAMP_NS, "camera_color_optical_frame"),
        "height": H, "width": W, "distortion_model": "plumb_bob",
        "d": np.zeros(5, np.float64), "k": k, "r": np.eye(3).ravel(),
        "p": np.zeros(12, np.float64), "binning_x": 0, "binning_y": 0,
        "roi": types["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    } | changes  # fmt: skip
    return cdr_encode(distro, CAMERA_INFO, build(distro, CAMERA_INFO, **fields))


def depth_image(distro: RosDistro, pixels: np.ndarray, encoding: str, **changes: Any) -> bytes:
    h, w = pixels.shape
    fields: dict[str, Any] = {
        "header": ros_header(distro, STAMP_NS, "camera_color_optical_frame"),
        "height": h, "width": w, "encoding": encoding, "is_bigendian": 0,
        "step": w * pixels.itemsize, "data": np.frombuffer(pixels.tobytes(), np.uint8),
    } | changes  # fmt: skip
    return cdr_encode(distro, IMAGE, build(distro, IMAGE, **fields))


INTR = DepthIntrinsics(fx=400.0, fy=410.0, cx=4.5, cy=3.25, width=W, height=H)


@pytest.mark.parametrize("distro", DISTROS)
def test_camera_info_gives_the_intrinsics_from_k(distro: RosDistro) -> None:
    msg = cdr_decode(distro, CAMERA_INFO, camera_info(distro))
    assert intrinsics_from_camera_info(msg) == INTR


def test_binning_and_a_region_of_interest_move_the_intrinsics_to_the_images_pixels() -> None:
    d = RosDistro.JAZZY
    roi = typestore_for(d).types["sensor_msgs/msg/RegionOfInterest"](
        x_offset=2, y_offset=1, height=4, width=6, do_rectify=False
    )
    msg = cdr_decode(d, CAMERA_INFO, camera_info(d, binning_x=2, binning_y=2, roi=roi))
    assert intrinsics_from_camera_info(msg) == DepthIntrinsics(200.0, 205.0, 1.25, 1.125, 3, 2)


@pytest.mark.parametrize("k", [np.zeros(9), np.array([np.nan, 0, 1, 0, 1, 1, 0, 0, 1])])
def test_an_uncalibrated_camera_info_is_refused(k: np.ndarray) -> None:
    d = RosDistro.JAZZY
    msg = cdr_decode(d, CAMERA_INFO, camera_info(d, k=k.astype(np.float64)))
    with pytest.raises(DecodeError, match="no usable intrinsics"):
        intrinsics_from_camera_info(msg)


@pytest.mark.parametrize("distro", DISTROS)
def test_16uc1_millimetres_become_a_depth_frame(distro: RosDistro) -> None:
    msg = cdr_decode(distro, IMAGE, depth_image(distro, MM, "16UC1"))
    frame = depth_from_image(msg, INTR, source="ros2")
    assert (frame.encoding, frame.width, frame.height) == ("16UC1", W, H)
    assert (frame.fx, frame.fy, frame.cx, frame.cy) == (400.0, 410.0, 4.5, 3.25)
    assert frame.header.stamp_ns == STAMP_NS
    assert frame.header.frame_id == "camera_color_optical_frame"
    assert frame.header.source == "ros2"
    np.testing.assert_array_equal(depth_metres(frame), MM.astype(np.float32) / 1000)
    assert DepthFrame.decode(frame.encode()) == frame


def test_32fc1_metres_padded_rows_and_big_endian_are_read_as_the_camera_meant() -> None:
    d = RosDistro.JAZZY
    metres = MM.astype(np.float32) / 1000
    metres[0, 0] = np.nan  # no reading stays no reading
    padded = np.zeros((H, W + 2), np.float32)
    padded[:, :W] = metres
    msg = cdr_decode(d, IMAGE, depth_image(d, padded, "32FC1", width=W, step=(W + 2) * 4))
    got = depth_metres(depth_from_image(msg, INTR, source="ros2"))
    np.testing.assert_array_equal(got, metres)  # NaN == NaN here
    big = MM.astype(">u2")
    msg = cdr_decode(d, IMAGE, depth_image(d, big, "16UC1", is_bigendian=1))
    assert depth_from_image(msg, INTR, source="r").data == MM.astype("<u2").tobytes()


@pytest.mark.parametrize(
    "changes", [{"step": 4}, {"height": 7}, {"data": np.zeros(3, np.uint8)}, {"width": 0}]
)
def test_a_depth_image_whose_size_step_and_data_disagree_is_a_decode_error(
    changes: dict[str, Any],
) -> None:
    d = RosDistro.JAZZY
    msg = cdr_decode(d, IMAGE, depth_image(d, MM, "16UC1", **changes))
    with pytest.raises(DecodeError, match="depth Image"):
        depth_from_image(msg, INTR, source="ros2")


# -- 3D out ---------------------------------------------------------------------------------------
def detections(*, depth: bool = True, frame_id: str = "camera_color_optical_frame") -> Detections:
    n = 3
    columns: dict[str, np.ndarray] = {}
    if depth:
        rows = np.array(
            [  # distance, x, y, z, size x, y, z
                [2.1, 0.5, -0.2, 2.0, 0.4, 1.7, 0.3],
                [np.nan] * 7,  # too few valid pixels: unknown
                [4.0, -1.0, 0.3, 3.8, 0.6, 0.5, 0.4],
            ],
            np.float32,
        )
        columns = {name: rows[:, i].copy() for i, name in enumerate(COLUMNS)}
    boxes = Boxes(
        xyxy=np.array([[1, 1, 10, 20], [2, 2, 4, 4], [30, 5, 40, 15]], np.float32),
        scores=np.array([0.9, 0.5, 0.7], np.float32),
        class_ids=np.array([0, 1, 0], np.int32),
        track_ids=np.array([7, -1, -1], np.int32),
        columns=columns,
    )
    header = Header(stamp_ns=STAMP_NS, frame_id=frame_id, seq=4, source="detector")
    return Detections(
        header=header, image_width=64, image_height=48, boxes=boxes,
        class_names=("person", "cup", "person")[:n],
    )  # fmt: skip


def size(detection: Any) -> tuple[float, float, float]:
    s = detection.bbox.size
    return (s.x, s.y, s.z)


def read_3d(distro: RosDistro, msg: Any) -> Any:
    """Through CDR and back by rosbags itself."""
    payload = cdr_encode(distro, DETECTION_3D_ARRAY, msg)
    return typestore_for(distro).deserialize_cdr(payload, DETECTION_3D_ARRAY)


@pytest.mark.parametrize("distro", DISTROS)
def test_3d_detections_in_the_optical_frame_leave_out_unknown_rows(distro: RosDistro) -> None:
    msg, unknown = detections_3d_to_ros(distro, detections())
    ros = read_3d(distro, msg)
    assert unknown == 1
    assert ros.header.frame_id == "camera_color_optical_frame"
    assert (ros.header.stamp.sec, ros.header.stamp.nanosec) == (1_700_000_000, 250_000_000)
    assert [d.id for d in ros.detections] == ["7", ""]
    first, second = ros.detections
    c = first.bbox.center
    assert (c.position.x, c.position.y, c.position.z) == pytest.approx((0.5, -0.2, 2.0))
    q = c.orientation
    assert (q.x, q.y, q.z, q.w) == (0.0, 0.0, 0.0, 1.0)
    assert size(first) == pytest.approx((0.4, 1.7, 0.3))
    hypothesis = first.results[0].hypothesis
    assert (hypothesis.class_id, hypothesis.score) == ("person", pytest.approx(0.9))
    assert first.results[0].pose.pose.position.z == pytest.approx(2.0)
    assert second.bbox.center.position.x == pytest.approx(-1.0)
    assert second.header.frame_id == "camera_color_optical_frame"


def test_3d_detections_in_the_robot_frame_use_the_cameras_mounting() -> None:
    d = RosDistro.JAZZY
    mount = Mounting(x_m=0.2, y_m=-0.1, height_m=0.5, yaw_deg=90.0)
    ros = read_3d(d, detections_3d_to_ros(d, detections(), frame_id="base_link", mount=mount)[0])
    assert ros.header.frame_id == "base_link"
    first = ros.detections[0]
    assert first.header.frame_id == "base_link"
    f, left, up = to_robot(*(np.array([v], np.float32) for v in (0.5, -0.2, 2.0)), mount)
    # Looking left (yaw 90): 2 m ahead of the camera is 2 m to the robot's left.
    assert (f[0], left[0], up[0]) == pytest.approx((0.2 + 0.5, -0.1 + 2.0, 0.5 + 0.2))
    p = first.bbox.center.position
    assert (p.x, p.y, p.z) == pytest.approx((f[0], left[0], up[0]))
    q = first.bbox.center.orientation
    assert (q.z, q.w) == pytest.approx((math.sin(math.pi / 4), math.cos(math.pi / 4)))
    # The size along the box's (forward, left, up): the optical (z, x, y) extents.
    assert size(first) == pytest.approx((0.3, 0.4, 1.7))


def test_detections_without_depth_columns_have_no_3d_message() -> None:
    assert has_3d(detections())
    assert not has_3d(detections(depth=False))
