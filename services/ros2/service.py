"""The ros2 service: the stack's keys to and from a ROS 2 robot over rmw_zenoh, no ROS install.

In:  sensor_msgs/Image or CompressedImage (``ros2.image_topic``) -> Frame on the camera key;
     sensor_msgs/LaserScan (``ros2.scan_topic``) -> the stack's LaserScan;
     with ``ros2.depth_in``, a depth sensor_msgs/Image and its CameraInfo
     (``ros2.depth_topic``, ``ros2.depth_info_topic``) -> DepthFrame on the camera's depth key.
Out: Detections -> vision_msgs/Detection2DArray (``ros2.detections_topic``), and those with
     depth columns -> vision_msgs/Detection3DArray (``ros2.detections_3d_topic``);
     the controller's Twist -> geometry_msgs/Twist or TwistStamped (``ros2.cmd_vel_topic``),
     only fresh, in order and from the controller; zero while its status says the e-stop is
     engaged or it is silent (common/command_gate.py);
     with ``ros2.depth_scans_out``, the depth scan stage's LaserScans (each camera's virtual
     scan, the remembered one, the known floor) -> sensor_msgs/LaserScan under
     ``ros2.scan_topic``.

Those image and detections topics are the first camera's (stack.camera); each further camera
has its own, under ``ros2.camera_namespace`` (services/ros2/contract.py::camera_topics), each mapped
to and from that camera's own keys.

Two sessions: the stack's bus (as principal ``ros2``) and the robot's ROS 2 graph. A payload on
a ROS key that is not valid CDR for its type, an image whose size and step disagree or an
unknown encoding is logged, counted as bad input and dropped. Losing the router while running
is survived: Zenoh reconnects, and meanwhile no frames arrive, so the controller's dead-man stop
commands zero.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from contextlib import ExitStack

from common.announce import announced_cameras
from common.bus import Declared, QoS, undeclare_all
from common.camera_announce import CameraAnnouncements
from common.clock import BOOT_ID, mono_s, now
from common.command_gate import CommandGate, Outcome
from common.errors import DecodeError, ImageError
from common.messages import (
    CameraAnnouncement,
    ControllerStatus,
    Detections,
    Frame,
    LaserScan,
    Twist,
)
from common.node import Node, Put, Tally
from rosmsg.convert import (
    DETECTION_2D_ARRAY,
    LASER_SCAN,
    TWIST,
    TWIST_STAMPED,
    cdr_decode,
    cdr_encode,
    detections_to_ros,
    scan_from_ros,
    scan_to_ros,
    twist_to_ros,
)
from rosmsg.depth import CAMERA_INFO, DETECTION_3D_ARRAY
from rosmsg.graph import RosGraph
from rosmsg.images import (
    COMPRESSED_IMAGE,
    IMAGE,
    frame_from_compressed_image,
    frame_from_image,
    frame_to_compressed_image,
)
from rosmsg.wire import SENSOR_DATA_QOS
from services.ros2 import contract
from services.ros2.contract import (
    ImageFormat,
    camera_topics,
    known_floor_topic,
    remembered_scan_topic,
    virtual_scan_topic,
)
from services.ros2.debug_image import FrameCache, debug_image
from services.ros2.depth_handlers import AnnouncementOf, DepthInbound, Detections3DToRos
from stack.config import Config

#: What the bridge says it is in the announcements of the cameras it bridges.
ANNOUNCED_SOURCE = "ros2"

#: Told of each frame a RosInbound put: ``(frame)``.
OnFrame = Callable[[Frame], None]


class RosInbound:
    """A ROS topic into the stack: CDR in, the stack's message out through ``put`` (each
    frame then told to ``on_frame``). Garbage is counted as ``bad_input.<topic>`` (the key's
    last chunk is the type hash)."""

    def __init__(
        self,
        config: Config,
        tally: Tally,
        ros_type: str,
        topic: str,
        put: Put,
        on_frame: OnFrame | None = None,
    ) -> None:
        self.distro = config.ros2.distro
        self.tally = tally
        self.ros_type = ros_type
        self.topic = topic
        self.put = put
        self.on_frame = on_frame
        self._counter = contract.topic_in(ros_type)

    def on_payload(self, key: str, cdr: memoryview) -> None:
        """``key``: the rmw_zenoh data key the sample came on."""
        frame: Frame | None = None
        try:
            msg = cdr_decode(self.distro, self.ros_type, cdr)
            if self.ros_type == LASER_SCAN:
                payload = scan_from_ros(msg, source="ros2").encode()
            else:
                if self.ros_type == IMAGE:
                    frame = frame_from_image(msg, source="ros2")
                else:
                    frame = frame_from_compressed_image(msg, source="ros2")
                payload = frame.encode()
        except DecodeError as exc:
            self.tally.bad_input(key, exc, topic=self.topic)
            return
        self.tally.counters.add(self._counter)
        self.put(payload)
        if frame is not None and self.on_frame is not None:
            self.on_frame(frame)


def announce_bridged(config: Config, announcements: CameraAnnouncements) -> dict[str, OnFrame]:
    """Announce each camera whose images the bridge puts on the stack's keys (none without
    ``ros2.image_in``): its rate, mounting (yaw, height, position) and field of view from its
    config, with
    ``ros2.depth_in`` as a depth camera, its size 0x0 until its first image, whose size and
    frame id are then announced. Returns, per camera, what to tell of each frame put."""
    s = config.ros2
    if not s.image_in:
        return {}
    told: dict[str, OnFrame] = {}
    for camera, c in config.all_cameras.items():
        announcements.announce(camera, c, depth=s.depth_in)

        def on_frame(frame: Frame, camera: str = camera) -> None:
            announcements.saw(camera, frame.width, frame.height, frame.header.frame_id)

        told[camera] = on_frame
    return told


class DetectionsToRos:
    """The detector's Detections of ``camera`` out as vision_msgs/Detection2DArray CDR, through
    ``put``."""

    def __init__(self, config: Config, tally: Tally, put: Put, camera: str) -> None:
        self.distro = config.ros2.distro
        self.tally = tally
        self.put = put
        self.key = tally.keys.detections(camera)

    def on_detections(self, payload: bytes) -> None:
        dets = self.tally.decode(self.key, Detections.decode, payload)
        if dets is None:
            return
        self.put(cdr_encode(self.distro, DETECTION_2D_ARRAY, detections_to_ros(self.distro, dets)))
        self.tally.counters.add(contract.DETECTIONS_OUT)


class CommandsToRos:
    """The controller's Twist out as geometry_msgs Twist or TwistStamped CDR, through ``put``,
    only as common/command_gate.py allows: fresh, in order, from the controller; zero while
    its status says the e-stop is engaged or is not fresh, or when the command is beyond
    ``ros2.max_command_*``; and one zero of its own when the controller goes silent. The
    window is the controller's dead-man (``controller.detection_timeout_s``).

    Called from Zenoh's threads (commands, statuses) and the service loop (``on_tick``): one
    lock keeps the gate and the order of what goes out."""

    def __init__(self, config: Config, tally: Tally, put: Put) -> None:
        self.settings = config.ros2
        self.tally = tally
        self.put = put
        self.ros_type = TWIST_STAMPED if self.settings.twist_stamped else TWIST
        self.gate = CommandGate(
            window_s=config.controller.detection_timeout_s,
            tolerance_s=config.stack.clock_tolerance_s,
            boot_id=BOOT_ID,
            max_linear=self.settings.max_command_linear,
            max_angular=self.settings.max_command_angular,
            source=tally.service,
        )
        self._lock = threading.Lock()

    def on_cmd_vel(self, payload: bytes) -> None:
        twist = self.tally.decode(self.tally.keys.cmd_vel(), Twist.decode, payload)
        if twist is not None:
            with self._lock:
                self._act(self.gate.on_command(twist, now()))

    def on_status(self, payload: bytes) -> None:
        key = self.tally.keys.controller_status()
        status = self.tally.decode(key, ControllerStatus.decode, payload)
        if status is not None:
            with self._lock:
                self._act(self.gate.on_status(status, now()))

    def on_tick(self) -> None:
        with self._lock:
            self._act(self.gate.on_tick(now()))

    def on_close(self) -> None:
        with self._lock:
            self._act(self.gate.on_close(now()))

    def _act(self, outcome: Outcome) -> None:
        if outcome.counter:
            self.tally.reject(outcome.counter, outcome.why)
        if outcome.send is not None:
            s = self.settings
            msg = twist_to_ros(s.distro, outcome.send, stamped=s.twist_stamped)
            self.put(cdr_encode(s.distro, self.ros_type, msg))
            self.tally.counters.add(contract.COMMANDS_OUT)


class DebugImages:
    """Each frame of ``camera`` with its detections drawn on it, as CompressedImage CDR through
    ``put``, at most ``ros2.debug_image_rate_hz``."""

    def __init__(self, config: Config, tally: Tally, put: Put, camera: str) -> None:
        self.settings = config.ros2
        self.max_frame_pixels = config.detector.max_frame_pixels
        self.tally = tally
        self.put = put
        self.frame_key = tally.keys.frame(camera)
        self.detections_key = tally.keys.detections(camera)
        self.frames = FrameCache()
        self._period_s = 1.0 / self.settings.debug_image_rate_hz
        self._due = 0.0

    def on_frame(self, payload: bytes) -> None:
        frame = self.tally.decode(self.frame_key, Frame.decode, payload)
        if frame is not None:
            self.frames.add(frame)

    def on_detections(self, payload: bytes) -> None:
        s = self.settings
        dets = self.tally.decode(self.detections_key, Detections.decode, payload)
        if dets is None:
            return
        frame = self.frames.take(dets.header.stamp_ns)
        if frame is None or mono_s() < self._due:
            return
        self._due = mono_s() + self._period_s
        try:
            drawn = debug_image(frame, dets, s.debug_jpeg_quality, self.max_frame_pixels)
        except ImageError as exc:
            self.tally.bad_input(self.frame_key, exc)
            return
        image = frame_to_compressed_image(s.distro, drawn)
        self.put(cdr_encode(s.distro, COMPRESSED_IMAGE, image))
        self.tally.counters.add(contract.DEBUG_IMAGES_OUT)


class ScansToRos:
    """One of the stack's LaserScans (``key``) out as sensor_msgs/LaserScan CDR, through
    ``put``: what the depth scan stage judged as obstacles, for rviz and the robot's own
    nodes."""

    def __init__(self, config: Config, tally: Tally, put: Put, key: str) -> None:
        self.distro = config.ros2.distro
        self.tally = tally
        self.put = put
        self.key = key

    def on_scan(self, payload: bytes) -> None:
        scan = self.tally.decode(self.key, LaserScan.decode, payload)
        if scan is None:
            return
        self.put(cdr_encode(self.distro, LASER_SCAN, scan_to_ros(self.distro, scan)))
        self.tally.counters.add(contract.DEPTH_SCANS_OUT)


def _bridge_depth_scans(config: Config, node: Node, graph: RosGraph) -> list[Declared]:
    """Map the depth scan stage's scans out, each on its own ROS topic: every camera's virtual
    scan (published by the stage for the depth cameras alone; a camera without depth leaves
    its topic silent), the remembered scan and the known floor."""
    s, keys = config.ros2, node.keys
    routes = [(keys.virtual_scan(c), virtual_scan_topic(s, c)) for c in config.all_cameras]
    routes += [
        (keys.remembered_scan(), remembered_scan_topic(s)),
        (keys.known_floor(), known_floor_topic(s)),
    ]
    subs: list[Declared] = []
    for key, topic in routes:
        out = ScansToRos(config, node, graph.publisher(topic, LASER_SCAN).put_cdr, key)
        subs.append(node.subscribe(key, out.on_scan))
    return subs


def _bridge_camera(
    config: Config,
    node: Node,
    graph: RosGraph,
    camera: str,
    on_frame: OnFrame | None,
    announced: AnnouncementOf,
) -> list[Declared]:
    """Map ``camera``'s images and depth in (each frame told to ``on_frame``) and its
    detections, 3D detections (by ``announced`` mountings) and debug images out, on its own
    ROS topics; the subscriptions on the stack's keys made for it."""
    s, keys = config.ros2, node.keys
    topics = camera_topics(s, config.stack.camera, camera)
    subs: list[Declared] = []
    if s.image_in:
        image_type = IMAGE if s.image_format is ImageFormat.RAW else COMPRESSED_IMAGE
        frames = node.publisher(keys.frame(camera), QoS.SENSOR)
        image_in = RosInbound(config, node, image_type, topics.image, frames.put, on_frame)
        graph.subscribe(topics.image, image_type, image_in.on_payload, SENSOR_DATA_QOS)
    if s.depth_in:
        depths = node.publisher(keys.depth(camera), QoS.SENSOR)
        depth_in = DepthInbound(
            config, node, depths.put, depth_topic=topics.depth, info_topic=topics.depth_info
        )
        graph.subscribe(topics.depth_info, CAMERA_INFO, depth_in.on_info, SENSOR_DATA_QOS)
        graph.subscribe(topics.depth, IMAGE, depth_in.on_depth, SENSOR_DATA_QOS)
    if s.debug_image_out:
        debug = graph.publisher(topics.debug_image, COMPRESSED_IMAGE)
        drawn = DebugImages(config, node, debug.put_cdr, camera)
        subs.append(node.subscribe(keys.detections(camera), drawn.on_detections))
        subs.append(node.subscribe(keys.frame(camera), drawn.on_frame))
    if s.detections_out:
        det_pub = graph.publisher(topics.detections, DETECTION_2D_ARRAY)
        dets_out = DetectionsToRos(config, node, det_pub.put_cdr, camera)
        subs.append(node.subscribe(keys.detections(camera), dets_out.on_detections))
    if s.detections_3d_out:
        pub_3d = graph.publisher(topics.detections_3d, DETECTION_3D_ARRAY)
        out_3d = Detections3DToRos(config, node, pub_3d.put_cdr, camera, announced)
        subs.append(node.subscribe(keys.detections(camera), out_3d.on_detections))
    return subs


def _nothing_announced(camera: str) -> CameraAnnouncement | None:
    return None


def run(config: Config, stop: threading.Event) -> int:
    """Bridge until ``stop`` is set."""
    s = config.ros2
    with ExitStack() as closing:
        node = closing.enter_context(Node("ros2", config))
        announcements = closing.enter_context(
            CameraAnnouncements(node.bus, node.keys, ANNOUNCED_SOURCE)
        )
        graph = closing.enter_context(RosGraph(s))
        keys = node.keys
        subs: list[Declared] = []
        closing.callback(undeclare_all, subs)  # every one declared, when it ends
        told = announce_bridged(config, announcements)
        announced: AnnouncementOf = _nothing_announced
        if s.detections_3d_out and s.detections_3d_frame:
            # Every camera's announced mounting (the bridge's own or another source's), for
            # 3D detections in the robot's frame.
            cameras = announced_cameras(
                node.bus,
                keys,
                on_bad=lambda key, exc: node.bad_input(key, exc, topic="camera_announcement"),
            )
            graph.on_close(cameras.close)
            announced = cameras.get
        for camera in config.all_cameras:
            subs += _bridge_camera(config, node, graph, camera, told.get(camera), announced)
        if s.depth_scans_out and config.controller.needs_depth:
            subs += _bridge_depth_scans(config, node, graph)
        if s.scan_in:
            scans = node.publisher(keys.scan(), QoS.SENSOR)
            scan_in = RosInbound(config, node, LASER_SCAN, s.scan_topic, scans.put)
            graph.subscribe(s.scan_topic, LASER_SCAN, scan_in.on_payload, SENSOR_DATA_QOS)
        cmds_out: CommandsToRos | None = None
        if s.cmd_vel_out:
            twist_type = TWIST_STAMPED if s.twist_stamped else TWIST
            cmd_pub = graph.publisher(s.cmd_vel_topic, twist_type)
            cmds_out = CommandsToRos(config, node, cmd_pub.put_cdr)
            subs.append(node.subscribe(keys.cmd_vel(), cmds_out.on_cmd_vel))
            subs.append(node.subscribe(keys.controller_status(), cmds_out.on_status))
        node.log.info(
            "in the ROS 2 graph (%s, domain %d) via %s as %s%s",
            s.distro, s.domain_id, ", ".join(s.router), s.namespace.rstrip("/"), s.node,
        )  # fmt: skip
        node.ready()
        # At the controller's rate: a silent controller's last command is stopped within
        # one period of outliving the window.
        while not stop.wait(1.0 / config.controller.control_rate_hz):
            if cmds_out is not None:
                cmds_out.on_tick()
            node.publish_counters()
        if cmds_out is not None:
            cmds_out.on_close()
    return 0
