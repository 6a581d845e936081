"""Property-based fuzzing of every subscribed key's handler (issue 13, item 7).

Each service runs for real (its ``run``, in a thread) on a Zenoh session that reaches nobody;
the test hands each of its subscription callbacks generated payloads itself, one at a time.
Nothing may raise, and the service's ``bad_input`` counter must grow by exactly one for each
payload the key's decoder rejects, and stay put for every other.
"""

from __future__ import annotations

import threading
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from common.messages import Detections, EStop, Frame, LaserScan, ServiceCounters, Twist
from common.node import Node
from common.settings import Config, ControllerSettings, Ros2Settings, SimSettings
from services.controller import service as controller
from services.detector import service as detector
from services.detector.types import DetectionResult
from services.metrics import service as metrics
from services.ros2 import service as ros2
from services.ros2.convert import (
    LASER_SCAN,
    TWIST,
    cdr_decode,
    cdr_encode,
    scan_to_ros,
    twist_to_ros,
)
from services.ros2.images import IMAGE, frame_to_image
from services.sim.robot_io import RosRobot, StackRobot
from tests.unit.fuzz import RecordingSession, payloads, samples, sessions, to_stack
from tests.unit.fuzz_serving import (
    NODE_SESSION,
    ROS_SESSION,
    fuzz_handler,
    message_handler,
    serving,
)


def test_the_controllers_handlers(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    config = Config(controller=ControllerSettings(estop_file=str(tmp_path / "estop.json")))
    with serving(monkeypatch, controller, config) as (node, (session,)):
        message_handler(node, session, "/detections", Detections)
        message_handler(node, session, "/scan", LaserScan)
        message_handler(node, session, "/estop", EStop)
    # Garbage on the e-stop key is a press: fail safe. The latch is on disk.
    assert '"engaged": true' in (tmp_path / "estop.json").read_text()


def test_the_metrics_services_handlers(monkeypatch: pytest.MonkeyPatch) -> None:
    with serving(monkeypatch, metrics, Config()) as (node, (session,)):
        message_handler(node, session, "/detections", Detections)
        message_handler(node, session, "/cmd_vel", Twist)
        message_handler(node, session, "/counters/", ServiceCounters)


class _IdleMailbox:
    """The detector's mailbox, never handing a frame to the loop: the handler alone is fuzzed
    here (what the loop does with a frame's pixels: tests/unit/common/test_fuzz_decoders.py)."""

    def put(self, _frame: Frame) -> bool:
        return False

    def take(self, timeout_s: float) -> None:
        threading.Event().wait(timeout_s)


def test_the_detectors_handler(monkeypatch: pytest.MonkeyPatch) -> None:
    stub = SimpleNamespace(
        backend=SimpleNamespace(name="stub", device="cpu", precision="fp32"),
        model_path=Path("stub.onnx"),
        names=("person",),
        info=SimpleNamespace(input_height=640, input_width=640),
        detect=lambda image: DetectionResult(
            names=("person",), image_width=image.shape[1], image_height=image.shape[0]
        ),
        close=lambda: None,
    )
    monkeypatch.setattr(detector, "open_detector", lambda _s: (stub, ""))
    monkeypatch.setattr(detector, "Mailbox", _IdleMailbox)
    with serving(monkeypatch, detector, Config()) as (node, (session,)):
        before = node.counters.get("frames_in")
        fed = message_handler(node, session, "/frame", Frame)
        assert node.counters.get("frames_in") - before == fed


def _ros_handler(
    node: Node, graph: RecordingSession, part: str, ros_type: str, valid: list[Any]
) -> None:
    def decode(payload: bytes) -> Any:
        return to_stack(cdr_decode(Ros2Settings().distro, ros_type, payload))

    cdr = [cdr_encode(Ros2Settings().distro, ros_type, m) for m in valid]
    [(key, handler)] = graph.handlers_of(part)
    strategy = payloads(ros_type, cdr, msgpack_shapes=False)
    fuzz_handler(node, handler, key, decode, strategy)


def test_the_ros2_bridges_handlers(monkeypatch: pytest.MonkeyPatch) -> None:
    config = Config(ros2=Ros2Settings(debug_image_out=True))
    distro = config.ros2.distro
    fresh = samples(stamp_ns=None)
    with serving(monkeypatch, ros2, config, ROS_SESSION) as (node, (stack, graph)):
        message_handler(node, stack, "/detections", Detections)  # the ROS and debug images
        message_handler(node, stack, "/cmd_vel", Twist)
        message_handler(node, stack, "/frame", Frame)  # the debug images' frames
        images = [frame_to_image(distro, f) for f in fresh[Frame] if f.encoding != "jpeg"]
        _ros_handler(node, graph, "::Image_", IMAGE, images)
        scans = [scan_to_ros(distro, s) for s in fresh[LaserScan]]
        _ros_handler(node, graph, "::LaserScan_", LASER_SCAN, scans)


def test_the_simulated_robots_command_handlers(monkeypatch: pytest.MonkeyPatch) -> None:
    config = Config(sim=SimSettings(ros2_robot=True))
    commands: list[Twist] = []

    def on_command(twist: Twist, _source: str) -> None:
        assert all(np.isfinite((*twist.linear, *twist.angular)))
        commands.append(twist)

    with sessions(monkeypatch, NODE_SESSION, ROS_SESSION) as opened, Node("sim", config) as node:
        stack_robot = StackRobot(config, node, on_command)
        with RosRobot(config, node, on_command):
            message_handler(node, opened[0], "/cmd_vel", Twist)
            twists = [twist_to_ros(config.ros2.distro, t) for t in samples(None)[Twist]]
            _ros_handler(node, opened[1], "::Twist_", TWIST, twists)
        stack_robot.close()
    assert commands  # valid commands got through to the robot
