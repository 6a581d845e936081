"""The ROS 2 bridge with an RGB-D camera: the robot's aligned depth image (16UC1 in mm, then
32FC1 in m) and its CameraInfo come in as DepthFrames with the CameraInfo's intrinsics, and
detections that carry depth columns go out as vision_msgs/Detection3DArray in the robot's base
frame, placed by the camera's announced mounting. The robot is played with plain Zenoh and
rosbags (test_ros2.py's RobotSide); this test stands in for the detector. One bridge serves
every check."""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import numpy as np
import pytest

from common.announce import Announced
from common.boxes import Boxes
from common.messages import CameraAnnouncement, DepthFrame, Detections, Frame, Header
from common.zenoh_bus import ZenohBus
from services.sim.cameras import sim_cameras
from tests.integration.conftest import Stack, free_port, wait_for
from tests.integration.test_ros2 import RobotSide, _typestore, _zenoh

pytestmark = pytest.mark.integration

DETS_3D_HASH = "RIHS01_793f5eab9595ac1c0da07873cc859db42eae51f0ee76056db8562515d830e018"
W, H = 16, 12
MM = (np.arange(W * H, dtype=np.uint16).reshape(H, W) * 10 + 400).astype(np.uint16)
METRES = np.full((H, W), 1.25, np.float32)
K = (300.0, 0.0, 7.5, 0.0, 310.0, 5.5, 0.0, 0.0, 1.0)
OPTICAL = "camera_color_optical_frame"


def _stamp(robot: RobotSide, t: int) -> Any:
    stamp = robot.ts.types["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)
    return robot.ts.types["std_msgs/msg/Header"](stamp=stamp, frame_id=OPTICAL)


def camera_info(robot: RobotSide) -> bytes:
    types = robot.ts.types
    msg = types["sensor_msgs/msg/CameraInfo"](
        header=_stamp(robot, time.time_ns()), height=H, width=W, distortion_model="plumb_bob",
        d=np.zeros(5), k=np.array(K), r=np.eye(3).ravel(), p=np.zeros(12),
        binning_x=0, binning_y=0,
        roi=types["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )  # fmt: skip
    return bytes(robot.ts.serialize_cdr(msg, "sensor_msgs/msg/CameraInfo"))


def depth_image(robot: RobotSide, pixels: np.ndarray, encoding: str, stamp_ns: int) -> bytes:
    msg = robot.ts.types["sensor_msgs/msg/Image"](
        header=_stamp(robot, stamp_ns), height=H, width=W, encoding=encoding, is_bigendian=0,
        step=W * pixels.itemsize, data=np.frombuffer(pixels.tobytes(), np.uint8),
    )  # fmt: skip
    return bytes(robot.ts.serialize_cdr(msg, "sensor_msgs/msg/Image"))


def detections_with_depth(camera: str) -> Detections:
    rows = np.array([[2.07, 0.5, -0.2, 2.0, 0.4, 1.7, 0.3], [np.nan] * 7], np.float32)
    names = ("distance_m", "x_m", "y_m", "z_m", "size_x_m", "size_y_m", "size_z_m")
    header = Header(stamp_ns=time.time_ns(), frame_id=OPTICAL, seq=1, source="test")
    return Detections(
        header=header, image_width=W, image_height=H, class_names=("person", "cup"),
        boxes=Boxes(xyxy=np.array([[1, 1, 8, 8], [9, 2, 12, 6]], np.float32),
                    scores=np.array([0.9, 0.6], np.float32),
                    class_ids=np.array([0, 1], np.int32), track_ids=np.array([3, -1], np.int32),
                    columns={n: rows[:, i].copy() for i, n in enumerate(names)}),
    )  # fmt: skip


def test_depth_comes_in_and_3d_detections_go_out(make_stack) -> None:  # type: ignore[no-untyped-def]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robot = RobotSide(endpoint)
    stop = threading.Event()
    try:
        stack: Stack = make_stack(
            supervisor={"services": ["ros2"]},
            ros2={"router": [endpoint], "scan_in": False, "depth_in": True,
                  "detections_3d_frame": "base_link"},
            camera={"mount_yaw_deg": 90.0},  # looking left
        )  # fmt: skip
        stack.wait_ready({"ros2"})
        camera = stack.config.stack.camera
        _, depths = stack.subscribe(stack.keys.depth(camera))
        out: list[Any] = []
        robot.node.declare_subscriber(
            f"0/detections_3d/vision_msgs::msg::dds_::Detection3DArray_/{DETS_3D_HASH}",
            lambda s: out.append(robot.ts.deserialize_cdr(
                s.payload.to_bytes(), "vision_msgs/msg/Detection3DArray")),
        )  # fmt: skip
        depth_topic = "camera/aligned_depth_to_color/image_raw"
        info_topic = "camera/aligned_depth_to_color/camera_info"
        sent: dict[int, str] = {}  # stamp -> encoding

        def drive() -> None:  # the depth camera at 10 Hz, 16UC1 then 32FC1; the "detector"
            i = 0
            while not stop.wait(0.1):
                i += 1
                stamp = time.time_ns()
                encoding = "16UC1" if i % 2 else "32FC1"
                sent[stamp] = encoding
                robot.put(info_topic, "sensor_msgs/msg/CameraInfo", camera_info(robot))
                pixels = MM if encoding == "16UC1" else METRES
                image = depth_image(robot, pixels, encoding, stamp)
                robot.put(depth_topic, "sensor_msgs/msg/Image", image)
                stack.session.put(stack.keys.detections(camera),
                                  detections_with_depth(camera).encode())  # fmt: skip

        threading.Thread(target=drive, daemon=True).start()

        def both_encodings() -> bool:
            return {DepthFrame.decode(p).encoding for p in list(depths)} == {"16UC1", "32FC1"}

        wait_for(both_encodings, 60, lambda: f"DepthFrames of both encodings:\n{stack.log()}")
        for frame in map(DepthFrame.decode, list(depths)):
            assert (frame.fx, frame.fy, frame.cx, frame.cy) == (300.0, 310.0, 7.5, 5.5)
            assert (frame.width, frame.height, frame.header.frame_id) == (W, H, OPTICAL)
            assert sent[frame.header.stamp_ns] == frame.encoding  # the ROS image's own stamp
            want = MM.astype("<u2") if frame.encoding == "16UC1" else METRES.astype("<f4")
            assert frame.data == want.tobytes()

        # Out: the known row only, in base_link by the announced mounting (yaw 90, height 0).
        wait_for(lambda: out, 60, lambda: f"a Detection3DArray:\n{stack.log()}")
        msg = out[-1]
        assert msg.header.frame_id == "base_link"
        assert [d.id for d in msg.detections] == ["3"]
        box = msg.detections[0].bbox
        p, size = box.center.position, box.size
        # 2 m ahead of a camera looking left is 2 m left of the robot; 0.5 m to its right is
        # 0.5 m ahead; 0.2 m above the optical centre (y down) is 0.2 m up.
        assert (p.x, p.y, p.z) == pytest.approx((0.5, 2.0, 0.2), abs=1e-6)
        assert (size.x, size.y, size.z) == pytest.approx((0.3, 0.4, 1.7), abs=1e-6)
        assert box.center.orientation.z == pytest.approx(math.sin(math.pi / 4))
        hypothesis = msg.detections[0].results[0].hypothesis
        assert (hypothesis.class_id, hypothesis.score) == ("person", pytest.approx(0.9))

        # The bridged camera is announced as a depth camera.
        heard = Announced(
            ZenohBus(stack.session),  # not closed here: the stack closes its session
            stack.keys.all_camera_announcements(),
            stack.keys.camera_announcement_parts,
            CameraAnnouncement.decode,
            lambda a: a.camera,
        )
        wait_for(lambda: (a := heard.get(camera)) is not None and a.depth, 20,
                 lambda: f"the camera announced with depth: {heard.current()}")  # fmt: skip
        heard.close()
        assert stack.stop() == 0, stack.log()
    finally:
        stop.set()
        robot.close()


def test_the_simulator_as_a_ros2_robot_with_a_depth_camera(make_stack) -> None:  # type: ignore[no-untyped-def]
    # The whole path over ROS 2: the simulator's depth image (16UC1) and CameraInfo on the ROS
    # topics, the bridge (depth_in) making DepthFrames of them with the simulator's intrinsics,
    # the detector pairing them with the colour frames the bridge brought in: a person 4 m
    # ahead (the "ahead" world, standing still without a controller) gets a distance. The
    # depth scan stage's virtual scan of those depth images goes back out to the ROS 2 graph
    # (ros2.depth_scans_out), where the robot's nodes see what was judged an obstacle.
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    stack: Stack = make_stack(
        supervisor={"services": ["sim", "ros2", "detector", "depthscan"]},
        sim={"ros2_robot": True, "depth": True, "laser": False, "scenario": "ahead"},
        ros2={"router": [endpoint], "scan_in": False, "depth_in": True},
        controller={"obstacle_sources": ["depth"], "no_laser": False},
        camera={"mount_height_m": 0.6},  # the bridge announces the mounting it is told
    )  # fmt: skip
    camera = stack.config.stack.camera
    virtual: list[Any] = []
    ts = _typestore()
    scan_type = "sensor_msgs/msg/LaserScan"
    listener = _zenoh("peer", connect=[endpoint])
    try:
        listener.declare_subscriber(
            f"0/scan/virtual/{camera}/sensor_msgs::msg::dds_::LaserScan_/"
            + ts.hash_rihs01(scan_type),
            lambda s: virtual.append(ts.deserialize_cdr(s.payload.to_bytes(), scan_type)),
        )
        _see_it_all(stack, camera, virtual)
    finally:
        listener.close()


def _see_it_all(stack: Stack, camera: str, virtual: list[Any]) -> None:
    _, depths = stack.subscribe(stack.keys.depth(camera))
    _, frames = stack.subscribe(stack.keys.frame(camera))
    _, dets = stack.subscribe(stack.keys.detections(camera))
    stack.wait_ready({"sim", "ros2", "detector"})

    def with_distance() -> list[float]:
        found = []
        for d in map(Detections.decode, list(dets)):
            names = np.asarray(d.class_names)[d.boxes.class_ids]
            if "distance_m" in d.boxes.columns:
                found += d.boxes.columns["distance_m"][names == "person"].tolist()
        return [x for x in found if math.isfinite(x)]

    wait_for(with_distance, 90, lambda: f"a person with a distance:\n{stack.log()}")
    # The person's front is 3.75 m away (4 m to their middle, 0.25 m radius).
    assert 3.4 < float(np.median(with_distance())) < 4.2, with_distance()
    spec = sim_cameras(stack.config)[0].spec
    colour = {Frame.decode(p).header.stamp_ns: Frame.decode(p).header for p in list(frames)}
    paired = 0
    for frame in map(DepthFrame.decode, list(depths)):
        assert frame.encoding == "16UC1"
        assert (frame.width, frame.height) == (spec.width, spec.height)
        assert (frame.fx, frame.fy) == pytest.approx((spec.focal_px, spec.focal_px))
        assert (frame.cx, frame.cy) == pytest.approx((spec.width / 2, spec.height / 2))
        if frame.header.stamp_ns in colour:  # the colour image's stamp and frame id
            assert frame.header.frame_id == colour[frame.header.stamp_ns].frame_id
            paired += 1
    assert paired > 0, "no depth image under its colour image's stamp"
    wait_for(lambda: virtual, 60, lambda: f"a virtual scan on ROS 2:\n{stack.log()}")
    scan = virtual[-1]
    ranges = np.asarray(scan.ranges)
    # The person's front, 3.75 m straight ahead, on the ray that looks there.
    straight = round(-scan.angle_min / scan.angle_increment)
    assert 3.4 < float(np.nanmin(ranges[straight - 1 : straight + 2])) < 4.2, ranges
    assert scan.header.frame_id, "a scan with no frame"
    assert stack.stop() == 0, stack.log()
