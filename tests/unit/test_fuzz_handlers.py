"""Property-based fuzzing of every subscribed key's handler (issue 13, item 7).

Each service's handlers are an object (``services/<name>/service.py``) built here with plain
collaborators: a ``Tally`` for the counters and a list for what would be published. The test
hands each handler generated payloads itself, one at a time, as Zenoh's callback would. Nothing
may raise, and the ``bad_input`` counter must grow by exactly one for each payload the key's
decoder rejects, and stay put for every other.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from common.counters import per_camera
from common.messages import (
    ControllerStatus,
    Detections,
    EStop,
    Frame,
    LaserScan,
    ServiceCounters,
    Twist,
)
from common.node import Tally
from rosmsg.convert import (
    LASER_SCAN,
    TWIST,
    cdr_decode,
    cdr_encode,
    scan_to_ros,
    twist_to_ros,
)
from rosmsg.images import IMAGE, frame_to_image
from rosmsg.wire import data_key
from services.controller.contract import ControllerSettings
from services.controller.handlers import ControllerHandlers
from services.detector.handlers import DetectorHandlers
from services.metrics.service import MetricsHandlers
from services.ros2.contract import Ros2Settings
from services.ros2.service import CommandsToRos, DebugImages, DetectionsToRos, RosInbound
from services.sim.contract import SimSettings
from services.sim.service import SimHandlers
from stack.config import Config
from tests.unit.announced import announcement
from tests.unit.fuzz import fuzz_handler, message_handler, payloads, samples, to_stack


def test_the_controllers_handlers(tmp_path: Path) -> None:
    config = Config(controller=ControllerSettings(estop_file=str(tmp_path / "estop.json")))
    tally = Tally("controller", config)
    handlers = ControllerHandlers(config, tally)
    keys = tally.keys
    camera = config.stack.camera
    handlers.set_cameras({camera: announcement(camera, config.camera)})
    on_detections = partial(handlers.on_detections, camera)
    message_handler(tally, on_detections, keys.detections(camera), Detections)
    message_handler(tally, handlers.on_scan, keys.scan(), LaserScan)
    message_handler(tally, handlers.on_estop, keys.estop(), EStop)
    # Garbage on the e-stop key is a press: fail safe. The latch is on disk.
    assert '"engaged": true' in (tmp_path / "estop.json").read_text()


def test_the_metrics_services_handlers() -> None:
    config = Config()
    tally = Tally("metrics", config)
    handlers = MetricsHandlers(config, tally)
    keys = tally.keys
    camera, counters = config.stack.camera, keys.all_counters()
    handlers.set_cameras({camera: announcement(camera, config.camera)})
    detections = keys.detections(camera)
    on_detections = partial(handlers.on_detections, camera, detections)
    message_handler(tally, on_detections, detections, Detections)
    message_handler(tally, handlers.on_cmd_vel, keys.cmd_vel(), Twist)
    message_handler(tally, partial(handlers.on_counters, counters), counters, ServiceCounters)


def test_the_detectors_handler() -> None:
    # The handler alone is fuzzed here: nothing takes frames from its slots (what the loop
    # does with a frame's pixels: tests/unit/common/test_fuzz_decoders.py).
    config = Config()
    tally = Tally("detector", config)
    handlers = DetectorHandlers(config, tally)
    camera = config.stack.camera
    before = tally.counters.get("frames_in")
    on_frame = partial(handlers.on_frame, camera)
    fed = message_handler(tally, on_frame, handlers.frame_keys[camera], Frame)
    assert tally.counters.get("frames_in") - before == fed
    assert tally.counters.get(per_camera("frames_in", camera)) == fed


def _ros_handler(
    tally: Tally,
    on_payload: Callable[[str, memoryview], None],
    topic: str,
    ros_type: str,
    valid: list[Any],
) -> None:
    s = Ros2Settings()

    def decode(payload: bytes) -> Any:
        return to_stack(cdr_decode(s.distro, ros_type, payload))

    key = data_key(s.domain_id, topic, ros_type, s.distro, s.namespace)
    cdr = [cdr_encode(s.distro, ros_type, m) for m in valid]
    strategy = payloads(ros_type, cdr, msgpack_shapes=False)
    fuzz_handler(tally, lambda payload: on_payload(key, memoryview(payload)), key, decode, strategy)


def test_the_ros2_bridges_handlers() -> None:
    config = Config(ros2=Ros2Settings(debug_image_out=True))
    s = config.ros2
    tally = Tally("ros2", config)
    keys, camera = tally.keys, config.stack.camera
    sent: list[bytes] = []  # what would be published, on the stack or to the robot
    debug = DebugImages(config, tally, sent.append, camera)
    dets_out = DetectionsToRos(config, tally, sent.append, camera)
    cmds_out = CommandsToRos(config, tally, sent.append)
    fresh = samples(stamp_ns=None)
    # The ROS and debug images' detections, then the commands, then the debug images' frames.
    message_handler(tally, debug.on_detections, keys.detections(camera), Detections)
    message_handler(tally, dets_out.on_detections, keys.detections(camera), Detections)
    message_handler(tally, cmds_out.on_cmd_vel, keys.cmd_vel(), Twist)
    message_handler(tally, cmds_out.on_status, keys.controller_status(), ControllerStatus)
    message_handler(tally, debug.on_frame, keys.frame(camera), Frame)
    images = [frame_to_image(s.distro, f) for f in fresh[Frame] if f.encoding != "jpeg"]
    image_in = RosInbound(config, tally, IMAGE, s.image_topic, sent.append)
    _ros_handler(tally, image_in.on_payload, s.image_topic, IMAGE, images)
    scans = [scan_to_ros(s.distro, scan) for scan in fresh[LaserScan]]
    scan_in = RosInbound(config, tally, LASER_SCAN, s.scan_topic, sent.append)
    _ros_handler(tally, scan_in.on_payload, s.scan_topic, LASER_SCAN, scans)


def test_the_simulated_robots_command_handlers() -> None:
    config = Config(sim=SimSettings(ros2_robot=True))
    tally = Tally("sim", config)
    commands: list[Twist] = []

    def on_command(twist: Twist, _source: str) -> None:
        assert all(np.isfinite((*twist.linear, *twist.angular)))
        commands.append(twist)

    handlers = SimHandlers(config, tally, on_command)
    cmd_vel = tally.keys.cmd_vel()
    message_handler(tally, partial(handlers.on_cmd_vel, source="fuzz"), cmd_vel, Twist)
    twists = [twist_to_ros(config.ros2.distro, t) for t in samples(None)[Twist]]
    _ros_handler(tally, handlers.on_ros_cmd_vel, config.ros2.cmd_vel_topic, TWIST, twists)
    assert commands  # valid commands got through to the robot
