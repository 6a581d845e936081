"""The ros2 service: the stack's keys to and from a ROS 2 robot over rmw_zenoh, no ROS install.

In:  sensor_msgs/Image or CompressedImage (``ros2.image_topic``) -> Frame on the camera key;
     sensor_msgs/LaserScan (``ros2.scan_topic``) -> the stack's LaserScan.
Out: Detections -> vision_msgs/Detection2DArray (``ros2.detections_topic``);
     the controller's Twist -> geometry_msgs/Twist or TwistStamped (``ros2.cmd_vel_topic``).

Two sessions: the stack's bus (as principal ``ros2``) and the robot's ROS 2 graph. A payload on
a ROS key that is not valid CDR for its type, an image whose size and step disagree or an
unknown encoding is logged, counted as bad input and dropped. Losing the router while running
is survived: Zenoh reconnects, and meanwhile no frames arrive, so the controller's dead-man stop
commands zero.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable

import zenoh

from common.bus import Publisher, QoS
from common.clock import mono_s
from common.errors import DecodeError, ImageError
from common.messages import Detections, Frame, LaserScan, Twist
from common.node import Node
from common.ros2_settings import ImageFormat
from common.settings import Config
from services.ros2.convert import (
    DETECTION_2D_ARRAY,
    LASER_SCAN,
    TWIST,
    TWIST_STAMPED,
    cdr_decode,
    detections_to_ros,
    scan_from_ros,
    twist_to_ros,
)
from services.ros2.debug_image import FrameCache, debug_image
from services.ros2.graph import RosGraph
from services.ros2.images import (
    COMPRESSED_IMAGE,
    IMAGE,
    frame_from_compressed_image,
    frame_from_image,
    frame_to_compressed_image,
)
from services.ros2.wire import SENSOR_DATA_QOS

_Subscriber = zenoh.Subscriber[None]

_IDLE_S = 1.0  # how often the loop publishes counters and looks at the stop flag


def command_in_range(twist: Twist, max_linear: float, max_angular: float) -> bool:
    """Whether every component of ``twist`` is within the bounds (m/s, rad/s)."""
    return all(abs(v) <= max_linear for v in twist.linear) and all(
        abs(w) <= max_angular for w in twist.angular
    )


def run(config: Config, stop: threading.Event) -> int:
    """Bridge until ``stop`` is set."""
    s = config.ros2
    with Node("ros2", config) as node, RosGraph(s) as graph:
        keys = node.keys
        subs: list[_Subscriber] = []

        def inbound(
            ros_type: str, convert: Callable[[str, memoryview], bytes], topic: str
        ) -> Callable[[str, memoryview], None]:
            """A ROS-side callback: decode, translate, publish on the stack; count garbage
            (as ``bad_input.<topic>``: the key's last chunk is the type hash)."""

            def on_payload(key: str, cdr: memoryview) -> None:
                try:
                    payload = convert(ros_type, cdr)
                except DecodeError as exc:
                    node.bad_input(key, exc, topic=topic)
                    return
                node.counters.add(f"{ros_type.rsplit('/', 1)[-1].lower()}_in")
                pubs[ros_type].put(payload)

            return on_payload

        pubs: dict[str, Publisher] = {}
        if s.image_in:
            image_type = IMAGE if s.image_format is ImageFormat.RAW else COMPRESSED_IMAGE
            pubs[image_type] = node.publisher(keys.frame(config.stack.camera), QoS.SENSOR)

            def to_frame(ros_type: str, cdr: memoryview) -> bytes:
                msg = cdr_decode(s.distro, ros_type, cdr)
                convert = frame_from_image if ros_type == IMAGE else frame_from_compressed_image
                frame: Frame = convert(msg, source="ros2")
                return frame.encode()

            graph.subscribe(
                s.image_topic,
                image_type,
                inbound(image_type, to_frame, s.image_topic),
                SENSOR_DATA_QOS,
            )
        if s.scan_in:
            pubs[LASER_SCAN] = node.publisher(keys.scan(), QoS.SENSOR)

            def to_scan(ros_type: str, cdr: memoryview) -> bytes:
                scan: LaserScan = scan_from_ros(cdr_decode(s.distro, ros_type, cdr), source="ros2")
                return scan.encode()

            graph.subscribe(
                s.scan_topic,
                LASER_SCAN,
                inbound(LASER_SCAN, to_scan, s.scan_topic),
                SENSOR_DATA_QOS,
            )
        if s.debug_image_out:
            subs.append(_debug_images(node, graph, config))
        if s.detections_out:
            det_pub = graph.publisher(s.detections_topic, DETECTION_2D_ARRAY)

            def on_detections(dets: Detections, _sample: zenoh.Sample) -> None:
                det_pub.put(detections_to_ros(s.distro, dets))
                node.counters.add("detections_out")

            det_key = keys.detections(config.stack.camera)
            subs.append(node.subscribe(det_key, Detections.decode, on_detections))
        if s.cmd_vel_out:
            twist_type = TWIST_STAMPED if s.twist_stamped else TWIST
            cmd_pub = graph.publisher(s.cmd_vel_topic, twist_type)

            def on_cmd(twist: Twist, _sample: zenoh.Sample) -> None:
                if not command_in_range(twist, s.max_command_linear, s.max_command_angular):
                    # When in doubt, zero: the robot gets a stop, never the absurd command.
                    node.reject(
                        "commands_out_of_range",
                        f"cmd_vel {twist.linear} {twist.angular} from {twist.header.source!r} "
                        "is beyond ros2.max_command_*: the robot is sent zero",
                    )
                    twist = dataclasses.replace(twist, linear=(0.0,) * 3, angular=(0.0,) * 3)
                cmd_pub.put(twist_to_ros(s.distro, twist, stamped=s.twist_stamped))
                node.counters.add("commands_out")

            subs.append(node.subscribe(keys.cmd_vel(), Twist.decode, on_cmd))
        node.log.info(
            "in the ROS 2 graph (%s, domain %d) via %s as %s%s",
            s.distro, s.domain_id, ", ".join(s.router), s.namespace.rstrip("/"), s.node,
        )  # fmt: skip
        node.ready()
        try:
            while not stop.wait(_IDLE_S):
                node.publish_counters()
        finally:
            for sub in subs:
                sub.undeclare()
    return 0


def _debug_images(node: Node, graph: RosGraph, config: Config) -> _Subscriber:
    """Publish each frame with its detections drawn on it, at most ``debug_image_rate_hz``.
    Returns the frames' subscriber; the detections' one is undeclared with the graph."""
    s = config.ros2
    frames = FrameCache()
    frame_key = node.keys.frame(config.stack.camera)
    pub = graph.publisher(s.debug_image_topic, COMPRESSED_IMAGE)
    period_s = 1.0 / s.debug_image_rate_hz
    due = 0.0

    def on_detections(dets: Detections, _sample: zenoh.Sample) -> None:
        nonlocal due
        frame = frames.take(dets.header.stamp_ns)
        if frame is None or mono_s() < due:
            return
        due = mono_s() + period_s
        try:
            drawn = debug_image(frame, dets, s.debug_jpeg_quality, config.detector.max_frame_pixels)
        except ImageError as exc:
            node.bad_input(frame_key, exc)
            return
        pub.put(frame_to_compressed_image(s.distro, drawn))
        node.counters.add("debug_images_out")

    dets_sub = node.subscribe(
        node.keys.detections(config.stack.camera), Detections.decode, on_detections
    )
    graph.on_close(dets_sub.undeclare)
    return node.subscribe(frame_key, Frame.decode, lambda f, _s: frames.add(f))
