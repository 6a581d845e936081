"""A ROS 2 robot, played with plain Zenoh and rosbags only, feeds the stack and obeys it.

Nothing here uses the bridge's own wire module: the keys, the attachment and the decoding come
from the rmw_zenoh format as documented (docs/ros2.md) and from rosbags, a CDR
implementation we did not write.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import xxhash
import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from skimage import data

from common.messages import Header, ServiceCounters, Twist
from tests.integration.conftest import REPO, Stack, free_port, wait_for

pytestmark = pytest.mark.integration

TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
DETS_HASH = "RIHS01_214274120007f4a683866481336b70310268cfa107aebe9d594a6acf75bda968"
ROS_SERVICES = {"ros2", "detector", "controller", "metrics"}


def _typestore() -> Any:
    store = get_typestore(Stores.ROS2_JAZZY)
    folder = REPO / "rosmsg" / "msg" / "vision_msgs"
    types: dict[str, Any] = {}
    for path in sorted(folder.glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"vision_msgs/msg/{path.stem}"))
    store.register(types)
    return store


def _zenoh(mode: str, **endpoints: list[str]) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    for name, value in endpoints.items():
        conf.insert_json5(f"{name}/endpoints", json.dumps(value))
    return zenoh.open(conf)


class RobotSide:
    """The robot's side: rmw_zenohd's stand-in (a router) and a node publishing its camera
    and laser, with the attachment every rmw_zenoh sample carries."""

    def __init__(self, endpoint: str) -> None:
        self.ts = _typestore()
        self.router = _zenoh("router", listen=[endpoint])
        self.node = _zenoh("peer", connect=[endpoint], listen=["tcp/127.0.0.1:0"])
        self.seq = 0

    def key(self, topic: str, ros_type: str) -> str:
        pkg, _, name = ros_type.split("/")
        return f"0/{topic}/{pkg}::msg::dds_::{name}_/{self.ts.hash_rihs01(ros_type)}"

    def put(self, topic: str, ros_type: str, payload: bytes) -> None:
        self.seq += 1
        attachment = struct.pack("<qqB16s", self.seq, time.time_ns(), 16, b"robot-gid-000001")
        self.node.put(self.key(topic, ros_type), payload, attachment=attachment)

    def header(self) -> Any:
        t = time.time_ns()
        stamp = self.ts.types["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)
        return self.ts.types["std_msgs/msg/Header"](stamp=stamp, frame_id="camera")

    def image(self, pixels: np.ndarray) -> bytes:
        h, w = pixels.shape[:2]
        mono = pixels.ndim == 2
        msg = self.ts.types["sensor_msgs/msg/Image"](
            header=self.header(), height=h, width=w, encoding="mono8" if mono else "rgb8",
            is_bigendian=0, step=w if mono else w * 3, data=pixels.reshape(-1),
        )  # fmt: skip
        return bytes(self.ts.serialize_cdr(msg, "sensor_msgs/msg/Image"))

    def scan(self) -> bytes:
        msg = self.ts.types["sensor_msgs/msg/LaserScan"](
            header=self.header(), angle_min=-2.35, angle_max=2.35, angle_increment=4.7 / 540,
            time_increment=0.0, scan_time=0.1, range_min=0.05, range_max=12.0,
            ranges=np.full(541, 5.0, np.float32), intensities=np.zeros(0, np.float32),
        )  # fmt: skip
        return bytes(self.ts.serialize_cdr(msg, "sensor_msgs/msg/LaserScan"))

    def close(self) -> None:
        self.node.close()
        self.router.close()


def test_a_ros2_robot_feeds_the_stack_and_obeys_it(make_stack, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robot = RobotSide(endpoint)
    stop = threading.Event()
    try:
        stack: Stack = make_stack(
            supervisor={"services": sorted(ROS_SERVICES)},
            ros2={"router": [endpoint], "debug_image_out": True},
        )
        stack.wait_ready(ROS_SERVICES)
        debug: list[Any] = []
        robot.node.declare_subscriber(
            robot.key("detections/image", "sensor_msgs/msg/CompressedImage"),
            lambda s: debug.append(robot.ts.deserialize_cdr(
                s.payload.to_bytes(), "sensor_msgs/msg/CompressedImage")),
        )  # fmt: skip
        dets: list[Any] = []
        cmds: list[Any] = []
        robot.node.declare_subscriber(
            f"0/detections/vision_msgs::msg::dds_::Detection2DArray_/{DETS_HASH}",
            lambda s: dets.append(robot.ts.deserialize_cdr(
                s.payload.to_bytes(), "vision_msgs/msg/Detection2DArray")),
        )  # fmt: skip
        robot.node.declare_subscriber(
            f"0/cmd_vel/geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}",
            lambda s: cmds.append(robot.ts.deserialize_cdr(
                s.payload.to_bytes(), "geometry_msgs/msg/Twist")),
        )  # fmt: skip
        _, counts = stack.subscribe(stack.keys.counters("ros2"))
        person = np.ascontiguousarray(data.camera())  # the cameraman, as a mono8 camera sends

        def drive() -> None:  # the robot's camera at 5 Hz, its laser at 10 Hz
            i = 0
            while not stop.wait(0.1):
                robot.put("scan", "sensor_msgs/msg/LaserScan", robot.scan())
                if i % 2 == 0:
                    robot.put("camera/rgb/image_raw", "sensor_msgs/msg/Image", robot.image(person))
                i += 1

        threading.Thread(target=drive, daemon=True).start()

        def saw_person() -> bool:
            return any(
                r.hypothesis.class_id == "person" and r.hypothesis.score > 0.6
                for d in list(dets) for det in d.detections for r in det.results
            )  # fmt: skip

        wait_for(
            saw_person,
            90,
            lambda: (
                f"a Detection2DArray holding a person ({len(dets)} arrays; bridge counters "
                f"{ServiceCounters.decode(counts[-1]).counters if counts else None})"
            ),
        )
        first = next(d for d in dets if d.detections)
        det = first.detections[0]
        assert det.bbox.size_x > 50 and det.bbox.size_y > 50
        assert 0 < det.bbox.center.position.x < 512 and det.id != ""  # a track id
        assert first.header.frame_id == "camera"
        wait_for(
            lambda: any(c.angular.z != 0.0 or c.linear.x != 0.0 for c in list(cmds)),
            30,
            "a cmd_vel reacting to the person",
        )

        # An absurd command on the stack's cmd_vel (anyone may put there without the secure
        # profile, and say they are the controller) reaches the robot as zero, never as it is.
        rogue = stack.session.declare_publisher(stack.keys.cmd_vel())

        def absurd() -> Twist:  # fresh each time: a stale or repeated one is not even sent
            header = Header(stamp_ns=time.time_ns(), frame_id="base_link", seq=1,
                            source="controller")  # fmt: skip
            return Twist(header=header, linear=(50.0, 0.0, 0.0))

        wait_for(
            lambda: (
                rogue.put(absurd().encode())
                or (
                    counts
                    and ServiceCounters.decode(counts[-1]).counters.get("commands_out_of_range", 0)
                    >= 3
                )
            ),
            20,
            "the bridge to refuse the absurd commands",
            poll=0.1,
        )
        assert all(abs(c.linear.x) <= 5.0 for c in list(cmds)), "50 m/s reached the robot"

        # The debug image: the frame with its boxes drawn, a jpeg as RViz and Foxglove take it.
        wait_for(lambda: debug, 30, "an annotated CompressedImage on /detections/image")
        assert "jpeg" in debug[0].format
        drawn = cv2.imdecode(np.asarray(debug[0].data, np.uint8), cv2.IMREAD_COLOR)
        assert drawn.shape == (512, 512, 3)
        assert not (drawn == drawn[..., :1]).all(), "no coloured box drawn on the grey photo"

        # The stack is in the ROS 2 graph: its node and endpoints have liveliness tokens.
        wanted = (("MS", "%camera%rgb%image_raw"), ("MS", "%scan"),
                  ("MP", "%detections"), ("MP", "%cmd_vel"))  # fmt: skip

        def graph_tokens() -> list[str]:
            replies = robot.node.liveliness().get("@ros2_lv/0/**", timeout=2.0)
            tokens = [str(r.ok.key_expr) for r in replies if r.ok is not None]
            node = any("/NN/" in t and t.endswith("/zenoh_yolo_stack") for t in tokens)
            endpoints = all(
                any(f"/{kind}/" in t and f"/{topic}/" in t for t in tokens)
                for kind, topic in wanted
            )
            return tokens if node and endpoints else []

        tokens = wait_for(graph_tokens, 20, "the bridge's node and endpoint liveliness tokens")
        # Each sample's GID is the one a ROS 2 graph derives from the publisher's token (XXH3-128
        # of the token, as rmw_zenoh_cpp's liveliness_utils.cpp): here, on the cmd_vel samples.
        cmd_gids: list[bytes] = []
        robot.node.declare_subscriber(
            f"0/cmd_vel/geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}",
            lambda s: cmd_gids.append(s.attachment.to_bytes()[17:33]) if s.attachment else None,
        )
        (cmd_token,) = [t for t in tokens if "/MP/" in t and "/%cmd_vel/" in t]
        expected = xxhash.xxh3_128_intdigest(cmd_token.encode()).to_bytes(16, "little")
        wait_for(lambda: cmd_gids, 20, "cmd_vel samples with their attachment")
        assert set(cmd_gids) == {expected}, (cmd_token, cmd_gids[:1], expected)

        # Garbage on the ROS keys is counted, and the bridge stays up.
        for _ in range(5):
            robot.put("camera/rgb/image_raw", "sensor_msgs/msg/Image", os.urandom(300))
            robot.put("scan", "sensor_msgs/msg/LaserScan", b"\x00\x01\x00\x00garbage")
        wait_for(
            lambda: (
                counts and ServiceCounters.decode(counts[-1]).counters.get("bad_input", 0) >= 10
            ),
            10,
            "the bridge to count the garbage",
        )
        assert "ros2" in stack.ready_services()
        n = len(dets)
        wait_for(lambda: len(dets) > n + 2, 30, "detections to go on after the garbage")

        # ... and `zstack query` shows it by topic, while the bridge's other counters go on
        # (a counter named after the key's type hash once froze them all, refused).
        def queried() -> dict[str, int]:
            done = subprocess.run(
                [sys.executable, "-m", "deploy.zstack", "query", "--config",
                 str(stack.config_path)],
                cwd=REPO, capture_output=True, text=True, timeout=60,
            )  # fmt: skip
            assert done.returncode == 0, done.stderr
            counters: dict[str, int] = json.loads(done.stdout)["counters"]
            return counters

        first = wait_for(
            lambda: (c := queried()).get("ros2.bad_input.camera.rgb.image_raw", 0) >= 5 and c,
            30,
            "the image topic's bad input in zstack query",
        )
        assert first.get("ros2.bad_input.scan", 0) >= 5, first
        assert not [k for k in first if "RIHS01" in k or k.startswith("metrics.refused")], first
        wait_for(
            lambda: queried().get("ros2.image_in", 0) > first["ros2.image_in"],
            30,
            "the bridge's other counters to go on",
        )
        assert stack.stop() == 0, stack.log()
    finally:
        stop.set()
        robot.close()


def test_no_router_is_one_line_and_a_lost_router_is_survived(make_stack, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    import subprocess
    import sys

    from tests.integration.conftest import write_config

    # No router at start-up: one clear line, a non-zero exit (the supervisor retries it).
    lonely = write_config(tmp_path, ros2={"router": [f"tcp/127.0.0.1:{free_port()}"],
                                          "router_timeout_s": 1.0})  # fmt: skip
    done = subprocess.run(
        [sys.executable, "-m", "services.ros2", "serve", "--config", str(lonely)],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert lines[-1].startswith("ros2: error: no rmw_zenoh router answered on "), done.stderr
    assert "Traceback" not in done.stderr

    # The router goes away while the stack runs, and comes back.
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robot = RobotSide(endpoint)
    stop = threading.Event()
    stack: Stack = make_stack(
        supervisor={"services": sorted(ROS_SERVICES)}, ros2={"router": [endpoint]}
    )
    stack.wait_ready(ROS_SERVICES)
    _, cmds = stack.subscribe(stack.keys.controller_status())
    person = np.ascontiguousarray(data.camera())
    current = {"robot": robot}

    def drive() -> None:
        while not stop.wait(0.2):
            r = current["robot"]
            if r is not None:
                r.put("camera/rgb/image_raw", "sensor_msgs/msg/Image", r.image(person))

    threading.Thread(target=drive, daemon=True).start()
    try:
        from common.messages import ControllerStatus

        def state() -> str:
            return ControllerStatus.decode(cmds[-1]).state if cmds else ""

        # Acting on the person seen through the bridge: centred ("tracking") or, if the last
        # box landed just outside the centre tolerance, turning to it (the robot here is a
        # stand-in that never turns, so either may last).
        acting = ("tracking", "turning")
        wait_for(lambda: state() in acting, 60, "acting on the person through the bridge")
        current["robot"] = None
        robot.close()  # the robot's router and node are gone
        wait_for(lambda: state() == "stale", 5, "the dead-man stop while the router is gone")
        assert "ros2" in stack.ready_services(), stack.log()
        robot = RobotSide(endpoint)  # back, on the same endpoint
        current["robot"] = robot
        wait_for(lambda: state() in acting, 60, "acting on the person once the router is back")
        assert stack.stop() == 0, stack.log()
        assert "ros2: exited" not in stack.log()
    finally:
        stop.set()
        if current["robot"] is not None:
            current["robot"].close()
