"""How the simulated robot talks: the stack's own messages, or ROS 2 over rmw_zenoh.

I/O. Either way the robot publishes its camera and laser and takes velocity commands; the
ROS 2 robot does it as a real one does (sensor_msgs Image and LaserScan, geometry_msgs Twist
or TwistStamped on the rmw_zenoh keys, through a router it hosts), so that every frame, scan
and command passes through the ``ros2`` bridge service.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Protocol

import zenoh

from common.bus import QoS, source_of
from common.clock import wall_ns
from common.errors import DecodeError
from common.lifecycle import Closing
from common.messages import Frame, LaserScan, Twist
from common.node import Node
from common.settings import Config
from services.ros2 import (
    IMAGE,
    LASER_SCAN,
    SENSOR_DATA_QOS,
    TWIST,
    TWIST_STAMPED,
    RosGraph,
    cdr_decode,
    frame_to_image,
    scan_to_ros,
    twist_from_ros,
)

OnCommand = Callable[[Twist, str], None]


class SensorOutput(Protocol):
    def frame(self, frame: Frame) -> None: ...
    def scan(self, scan: LaserScan) -> None: ...


class StackRobot:
    """Sensors on the stack's keys; commands from the controller's cmd_vel key."""

    def __init__(self, config: Config, node: Node, on_command: OnCommand) -> None:
        keys = node.keys
        self._frame = node.publisher(keys.frame(config.stack.camera), QoS.SENSOR)
        self._scan = node.publisher(keys.scan(), QoS.SENSOR)

        def on_cmd(twist: Twist, sample: zenoh.Sample) -> None:
            on_command(twist, source_of(sample))

        self._sub = node.subscribe(keys.cmd_vel(), Twist.decode, on_cmd)

    def frame(self, frame: Frame) -> None:
        self._frame.put(frame.encode())

    def scan(self, scan: LaserScan) -> None:
        self._scan.put(scan.encode())

    def close(self) -> None:
        self._sub.undeclare()


class RosRobot(Closing):
    """Sensors as ROS 2 messages on the rmw_zenoh keys of ``config.ros2``'s topics; commands
    taken from its cmd_vel topic. Hosts the graph's router on ``ros2.router``."""

    def __init__(self, config: Config, node: Node, on_command: OnCommand) -> None:
        s = config.ros2
        self._distro = s.distro
        self._graph = RosGraph(dataclasses.replace(s, node="sim_robot"), host=True)
        self._image = self._graph.publisher(s.image_topic, IMAGE, SENSOR_DATA_QOS)
        self._scan = self._graph.publisher(s.scan_topic, LASER_SCAN, SENSOR_DATA_QOS)
        twist_type = TWIST_STAMPED if s.twist_stamped else TWIST

        def on_payload(key: str, cdr: memoryview) -> None:
            try:
                msg = cdr_decode(s.distro, twist_type, cdr)
                twist = twist_from_ros(msg, source="ros2", received_ns=wall_ns())
            except DecodeError as exc:
                node.bad_input(key, exc)
                return
            on_command(twist, "ros2")

        self._graph.subscribe(s.cmd_vel_topic, twist_type, on_payload)

    def frame(self, frame: Frame) -> None:
        self._image.put(frame_to_image(self._distro, frame))

    def scan(self, scan: LaserScan) -> None:
        self._scan.put(scan_to_ros(self._distro, scan))

    def close(self) -> None:
        self._graph.close()
