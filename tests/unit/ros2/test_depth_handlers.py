"""The bridge's depth handlers: depth in (a depth image and its CameraInfo -> a DepthFrame,
counting what it drops) and 3D detections out (``Detection3DArray``, in the camera's or the
robot's frame), through CDR written by rosbags and by rclpy. The translations themselves:
tests/unit/rosmsg/test_depth.py."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given

from common.messages import CameraAnnouncement, DepthFrame, Detections
from common.node import Tally
from perception.depth import depth_metres
from rosmsg.depth import CAMERA_INFO, DETECTION_3D_ARRAY
from rosmsg.distro import RosDistro
from rosmsg.images import IMAGE
from rosmsg.typestore import typestore_for
from services.ros2 import contract
from services.ros2.depth_handlers import DepthInbound, Detections3DToRos
from stack.config import Config
from tests.unit.fuzz import fuzz, message_handler, payloads
from tests.unit.rosmsg.test_depth import MM, STAMP_NS, camera_info, depth_image, detections


class Puts(list[bytes]):
    def put(self, payload: bytes) -> None:
        self.append(payload)


def test_depth_in_holds_back_until_a_camera_info_and_counts_what_it_drops() -> None:
    d = RosDistro.JAZZY
    tally = Tally("ros2", Config())
    out = Puts()
    inbound = DepthInbound(
        Config(), tally, out.put, depth_topic="/camera/depth", info_topic="/camera/info"
    )
    good = memoryview(depth_image(d, MM, "16UC1"))
    inbound.on_depth("k", good)  # no CameraInfo yet: held back, never guessed
    assert out == [] and tally.counters.get(contract.DEPTH_WITHOUT_INFO) == 1
    inbound.on_info("i", memoryview(b"\x00\x01\x00\x00garbage"))
    inbound.on_info("i", memoryview(camera_info(d, k=np.zeros(9))))  # uncalibrated
    assert tally.counters.get("bad_input.camera.info") == 2
    inbound.on_depth("k", good)
    assert out == []
    inbound.on_info("i", memoryview(camera_info(d)))
    assert tally.counters.get(contract.DEPTH_INFO_IN) == 1
    inbound.on_depth("k", good)
    assert len(out) == 1
    frame = DepthFrame.decode(out[0])
    assert (frame.fx, frame.cy, frame.header.stamp_ns) == (400.0, 3.25, STAMP_NS)
    # Another encoding, another size, garbage: each counted and dropped.
    inbound.on_depth("k", memoryview(depth_image(d, MM.astype(np.uint8), "mono8")))
    inbound.on_depth("k", memoryview(depth_image(d, MM[:, :4].copy(), "16UC1")))
    inbound.on_depth("k", memoryview(depth_image(d, MM, "16UC1", step=3)))
    inbound.on_depth("k", memoryview(b"\x00\x01\x00\x00\xff"))
    assert len(out) == 1
    assert tally.counters.get(contract.DEPTH_BAD_ENCODING) == 1
    assert tally.counters.get(contract.DEPTH_SIZE_MISMATCH) == 1
    assert tally.counters.get("bad_input.camera.depth") == 2
    assert tally.counters.get(contract.DEPTH_OUT) == 1


def test_3d_out_sends_only_depth_detections_and_needs_the_mounting_for_a_robot_frame() -> None:
    d = RosDistro.JAZZY
    tally = Tally("ros2", Config())
    out = Puts()
    announced: dict[str, CameraAnnouncement] = {}
    optical = Detections3DToRos(Config(), tally, out.put, "camera", announced.get)
    optical.on_detections(detections(depth=False).encode())  # 2D only: nothing
    optical.on_detections(b"garbage")
    assert out == [] and tally.counters.get("bad_input") == 1
    optical.on_detections(detections().encode())
    assert len(out) == 1
    assert tally.counters.get(contract.DETECTIONS_3D_OUT) == 1
    assert tally.counters.get(contract.DETECTIONS_3D_UNKNOWN) == 1
    ros = typestore_for(d).deserialize_cdr(out[0], DETECTION_3D_ARRAY)
    assert len(ros.detections) == 2

    config = Config()
    config = dataclasses.replace(
        config, ros2=dataclasses.replace(config.ros2, detections_3d_frame="base_link")
    )
    robot = Detections3DToRos(config, tally, out.put, "camera", announced.get)
    robot.on_detections(detections().encode())  # not announced: where it stands is unknown
    assert len(out) == 1 and tally.counters.get(contract.DETECTIONS_3D_UNMOUNTED) == 1
    announced["camera"] = CameraAnnouncement(
        camera="camera", rate_hz=10.0, mount_yaw_deg=180.0, mount_height_m=0.4, mount_x_m=-0.3
    )
    robot.on_detections(detections().encode())
    ros = typestore_for(d).deserialize_cdr(out[1], DETECTION_3D_ARRAY)
    p = ros.detections[0].bbox.center.position
    # A rear camera: 2 m ahead of it is 2 m behind the robot, its right the robot's left.
    assert (ros.header.frame_id, p.x, p.y, p.z) == pytest.approx(
        ("base_link", -0.3 - 2.0, 0.5, 0.4 + 0.2)
    )


def test_mutated_depth_images_and_camera_infos_never_escape_the_handler() -> None:
    """Truncated, bit-flipped and random CDR on both topics: a DepthFrame or a count, never an
    exception into Zenoh's thread."""
    d = RosDistro.JAZZY
    tally = Tally("ros2", Config())
    out = Puts()
    inbound = DepthInbound(Config(), tally, out.put, depth_topic="/d", info_topic="/i")
    infos = [camera_info(d)]
    images = [depth_image(d, MM, "16UC1"), depth_image(d, MM.astype(np.float32) / 1000, "32FC1")]

    @fuzz(100)
    @given(info=payloads(CAMERA_INFO, infos, msgpack_shapes=False),
           image=payloads(IMAGE, images, msgpack_shapes=False))  # fmt: skip
    def check(info: bytes, image: bytes) -> None:
        inbound.on_info("i", memoryview(info))
        inbound.on_depth("d", memoryview(image))

    check()
    for payload in out:
        DepthFrame.decode(payload)  # what went out is a valid message


def test_depth_and_camera_info_as_ros_2_itself_serializes_them() -> None:
    """CDR written by rclpy (``data/make_rclpy_cdr.py``: ROS 2 Kilted's own serializer), not
    by rosbags: the bridge reads its intrinsics, stamp, frame id and every depth value."""
    data = Path(__file__).with_name("data")
    tally = Tally("ros2", Config())
    out = Puts()
    inbound = DepthInbound(Config(), tally, out.put, depth_topic="/d", info_topic="/i")
    inbound.on_info("i", memoryview((data / "rclpy_camera_info.cdr").read_bytes()))
    for encoding in ("16UC1", "32FC1"):
        inbound.on_depth("d", memoryview((data / f"rclpy_{encoding}.cdr").read_bytes()))
    frames = [DepthFrame.decode(p) for p in out]
    assert [f.encoding for f in frames] == ["16UC1", "32FC1"]
    ramp_mm = np.arange(16 * 12, dtype=np.uint16).reshape(12, 16) * 10 + 400
    for frame in frames:
        assert (frame.fx, frame.fy, frame.cx, frame.cy) == (300.0, 310.0, 7.5, 5.5)
        assert (frame.width, frame.height) == (16, 12)
        assert frame.header.stamp_ns == 1_700_000_000_000_000_123
        assert frame.header.frame_id == "camera_color_optical_frame"
        np.testing.assert_allclose(depth_metres(frame), ramp_mm / 1000, rtol=1e-6)


@pytest.mark.parametrize("frame", ["", "base_link"])
def test_fuzzed_detections_never_escape_the_3d_handler(frame: str) -> None:
    config = Config()
    config = dataclasses.replace(
        config, ros2=dataclasses.replace(config.ros2, detections_3d_frame=frame)
    )
    tally = Tally("ros2", config)
    out = Puts()
    mount = CameraAnnouncement(camera="camera", rate_hz=10.0, mount_yaw_deg=30.0)
    handler = Detections3DToRos(config, tally, out.put, "camera", {"camera": mount}.get)
    message_handler(tally, handler.on_detections, handler.key, Detections)
    handler.on_detections(detections().encode())  # and one with depth, surely
    assert out
    for payload in out:  # what went out reads back as a Detection3DArray
        typestore_for(RosDistro.JAZZY).deserialize_cdr(payload, DETECTION_3D_ARRAY)
