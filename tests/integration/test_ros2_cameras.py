"""The ROS 2 bridge with two cameras: each camera's images come in on its own ROS topic onto its
own stack key, and its detections go out on its own ROS topic. The robot is played with plain
Zenoh and rosbags (test_ros2.py's RobotSide); this test stands in for the detector, putting
each camera's detections on its own key, so that only the bridge's mapping is under test."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
import pytest

from common.announce import Announced
from common.boxes import Boxes
from common.messages import CameraAnnouncement, Detections, Frame, Header
from common.zenoh_bus import ZenohBus
from tests.integration.conftest import Stack, free_port, wait_for
from tests.integration.test_ros2 import DETS_HASH, RobotSide

pytestmark = pytest.mark.integration

# Each camera's ROS topics (ros2.camera_namespace = "/{camera}" for the rear), the size of the
# images its robot camera sends, and the one class its "detector" finds: told apart on arrival.
CAMERAS: dict[str, dict[str, Any]] = {
    "front": {"image": "camera/rgb/image_raw", "detections": "detections",
              "size": (32, 16), "label": "person"},
    "rear": {"image": "rear/camera/rgb/image_raw", "detections": "rear/detections",
             "size": (48, 24), "label": "dog"},
}  # fmt: skip


def _detections(camera: str, seq: int) -> Detections:
    w, h = CAMERAS[camera]["size"]
    header = Header(stamp_ns=time.time_ns(), frame_id=camera, seq=seq, source="test")
    return Detections(
        header=header, image_width=w, image_height=h, class_names=(CAMERAS[camera]["label"],),
        boxes=Boxes(xyxy=np.array([[1, 1, 8, 8]], np.float32), scores=np.array([0.9], np.float32),
                    class_ids=np.zeros(1, np.int32)),
    )  # fmt: skip


def test_each_camera_has_its_own_ros_topics(make_stack) -> None:  # type: ignore[no-untyped-def]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robot = RobotSide(endpoint)
    stop = threading.Event()
    try:
        stack: Stack = make_stack(
            supervisor={"services": ["ros2"]},
            ros2={"router": [endpoint], "scan_in": False},
            **{"cameras.rear": {"mount_yaw_deg": 180.0}},
        )
        stack.wait_ready({"ros2"})
        frames = {name: stack.subscribe(stack.keys.frame(name))[1] for name in CAMERAS}
        out: dict[str, list[Any]] = {name: [] for name in CAMERAS}
        for name, cam in CAMERAS.items():
            robot.node.declare_subscriber(
                f"0/{cam['detections']}/vision_msgs::msg::dds_::Detection2DArray_/{DETS_HASH}",
                lambda s, got=out[name]: got.append(robot.ts.deserialize_cdr(
                    s.payload.to_bytes(), "vision_msgs/msg/Detection2DArray")),
            )  # fmt: skip

        def drive() -> None:  # each robot camera at 10 Hz, and each camera's detections
            seq = 0
            while not stop.wait(0.1):
                seq += 1
                for name, cam in CAMERAS.items():
                    w, h = cam["size"]
                    pixels = np.full((h, w), 100, np.uint8)
                    robot.put(cam["image"], "sensor_msgs/msg/Image", robot.image(pixels))
                    stack.session.put(stack.keys.detections(name), _detections(name, seq).encode())

        threading.Thread(target=drive, daemon=True).start()
        wait_for(
            lambda: all(len(frames[n]) >= 3 and len(out[n]) >= 3 for n in CAMERAS),
            60,
            lambda: (
                f"frames and detections of both cameras (frames "
                f"{ {n: len(f) for n, f in frames.items()} }, detections "
                f"{ {n: len(d) for n, d in out.items()} }):\n{stack.log()}"
            ),
        )
        for name, cam in CAMERAS.items():
            # In: the robot camera's images on this camera's key, and only there.
            sizes = {(f.width, f.height) for f in map(Frame.decode, list(frames[name]))}
            assert sizes == {cam["size"]}, (name, sizes)
            # Out: this camera's detections on its own ROS topic, and only there.
            labels = {r.hypothesis.class_id for d in list(out[name]) for det in d.detections
                      for r in det.results}  # fmt: skip
            assert labels == {cam["label"]}, (name, labels)
            assert {d.header.frame_id for d in list(out[name])} == {name}

        # Each camera bridged in is announced: the config's rate and mounting, its images' size.
        heard = Announced(
            ZenohBus(stack.session),  # not closed here: the stack closes its session
            stack.keys.all_camera_announcements(),
            stack.keys.camera_announcement_parts,
            CameraAnnouncement.decode,
            lambda a: a.camera,
        )
        sized = {
            name: (cam["size"], 180.0 if name == "rear" else 0.0) for name, cam in CAMERAS.items()
        }
        wait_for(
            lambda: (
                {
                    c: ((a.width, a.height), a.mount_yaw_deg)
                    for c, a in heard.current().items()
                    if a.source == "ros2" and a.rate_hz == stack.config.camera.rate_hz
                }
                == sized
            ),
            20,
            lambda: f"both cameras announced by the bridge: {heard.current()}",
        )
        heard.close()

        # Both cameras' endpoints are in the ROS 2 graph.
        wanted = [("MS", "%camera%rgb%image_raw"), ("MS", "%rear%camera%rgb%image_raw"),
                  ("MP", "%detections"), ("MP", "%rear%detections")]  # fmt: skip

        def endpoints() -> bool:
            replies = robot.node.liveliness().get("@ros2_lv/0/**", timeout=2.0)
            tokens = [str(r.ok.key_expr) for r in replies if r.ok is not None]
            return all(
                any(f"/{kind}/" in t and f"/{topic}/" in t for t in tokens)
                for kind, topic in wanted
            )

        wait_for(endpoints, 20, "both cameras' ROS 2 endpoints' liveliness tokens")
        assert stack.stop() == 0, stack.log()
    finally:
        stop.set()
        robot.close()
