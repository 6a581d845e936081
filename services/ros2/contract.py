"""The ROS 2 bridge's contract: its counters and what it puts and reads. Imports only
``common`` and the distributions of the message library (``rosmsg/distro.py``).

The bridge feeds the robot's cameras (each announced) and laser into the stack, and the stack's
detections and commands out to the robot (held at zero by the controller's status).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Annotated

from common.access import Access, Shape, service_access
from common.counters import COMMON
from common.errors import ConfigError
from common.setting_checks import Length, Range, check_bounds, check_lengths, enum_field
from rosmsg.distro import RosDistro

DETECTIONS_OUT = "detections_out"
COMMANDS_OUT = "commands_out"
DEBUG_IMAGES_OUT = "debug_images_out"
#: Depth in (``ros2.depth_in``): CameraInfos taken; DepthFrames put; depth images dropped
#: because no CameraInfo of their camera had come yet, because their encoding is neither 16UC1
#: nor 32FC1, or because their size is not the CameraInfo's.
DEPTH_INFO_IN = "depth_info_in"
DEPTH_OUT = "depth_out"
DEPTH_WITHOUT_INFO = "depth_without_info"
DEPTH_BAD_ENCODING = "depth_bad_encoding"
DEPTH_SIZE_MISMATCH = "depth_size_mismatch"
#: 3D out (``ros2.detections_3d_out``): Detection3DArrays sent; detections left out of them
#: for an unknown depth (NaN); Detections not sent for want of the camera's announced mounting
#: (``ros2.detections_3d_frame`` set).
DETECTIONS_3D_OUT = "detections_3d_out"
DETECTIONS_3D_UNKNOWN = "detections_3d_unknown"
DETECTIONS_3D_UNMOUNTED = "detections_3d_unmounted"
#: The depth scan stage's scans out (``ros2.depth_scans_out``): each camera's virtual scan,
#: the remembered one and the known floor, as sensor_msgs/LaserScan.
DEPTH_SCANS_OUT = "depth_scans_out"


def topic_in(ros_type: str) -> str:
    """The counter of messages of ``ros_type`` (``sensor_msgs/msg/Image``) taken in:
    ``image_in``."""
    return f"{ros_type.rsplit('/', 1)[-1].lower()}_in"


#: Its own counts; the command gate (common/command_gate.py) adds ``commands_<why>`` and
#: ``stops_<why>`` for what it refused or replaced by zero.
COUNTERS = frozenset(
    {
        *COMMON,
        DETECTIONS_OUT,
        COMMANDS_OUT,
        DEBUG_IMAGES_OUT,
        DEPTH_INFO_IN,
        DEPTH_OUT,
        DEPTH_WITHOUT_INFO,
        DEPTH_BAD_ENCODING,
        DEPTH_SIZE_MISMATCH,
        DETECTIONS_3D_OUT,
        DETECTIONS_3D_UNKNOWN,
        DETECTIONS_3D_UNMOUNTED,
        DEPTH_SCANS_OUT,
    }
)
PER_CAMERA: frozenset[str] = frozenset()

SERVICE = "ros2"
#: It feeds a live robot's sensors into the stack: no recording may be played onto it.
LIVE_SENSOR = True
#: Its work loop publishes counters on every pass: its heartbeat (deploy/watchdog.py).
HEARTBEAT = True


def access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    return {
        SERVICE: service_access(
            keys,
            SERVICE,
            *shape.frames(),
            *(keys.depth(camera) for camera in shape.cameras),
            keys.scan(),
            read=(
                keys.all_frames(),
                keys.all_detections(),
                keys.cmd_vel(),
                keys.controller_status(),
                # What the depth scan stage judged as obstacles, out to ROS 2.
                keys.all_virtual_scans(),
                keys.remembered_scan(),
                keys.known_floor(),
            ),
            token=(keys.health(SERVICE), *map(keys.camera_announcements_of, shape.cameras)),
            # The cameras' mountings, for 3D detections in the robot's frame.
            watch=(keys.all_camera_announcements(),),
        )
    }


# -- settings -------------------------------------------------------------------------------------
class ImageFormat(StrEnum):
    RAW = "raw"  # sensor_msgs/msg/Image: bgr8, rgb8 or mono8
    COMPRESSED = "compressed"  # sensor_msgs/msg/CompressedImage: jpeg


#: In ``ros2.camera_namespace``: where the camera's name goes.
CAMERA_FIELD = "{camera}"
_TOPIC = re.compile(r"^/?[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*$")
# A tf frame id: no spaces, no wildcards, no leading '/' (tf2 refuses one).
_FRAME_ID = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_./-]{0,127}$")


def _topic(name: str, value: str) -> None:
    if not _TOPIC.match(value):
        raise ConfigError(f"ros2.{name} {value!r} is not a ROS 2 topic name (e.g. /camera/image)")


@dataclass(frozen=True, slots=True, kw_only=True)
class Ros2Settings:
    """The bridge between the stack's keys and a ROS 2 graph (rmw_zenoh, no ROS install).

    ``router`` are the rmw_zenoh router's endpoints (``rmw_zenohd`` listens on port 7447);
    the bridge also listens on ``listen`` so that the robot's nodes (peers) reach it directly,
    as rmw_zenoh's own nodes do (use ``tcp/0.0.0.0:0`` when the router is on another host);
    ``domain_id``, ``distro``, ``node`` and ``namespace`` place the bridge in the graph. Each
    direction can be turned off: images and scans in (``image_in``, ``scan_in``), detections
    and commands out (``detections_out``, ``cmd_vel_out``). ``twist_stamped`` publishes
    ``geometry_msgs/msg/TwistStamped`` instead of ``Twist`` (many Jazzy robots take it).
    ``debug_image_out`` publishes each frame with its detections drawn on it (boxes, class,
    score, track id) as a jpeg ``CompressedImage`` on ``debug_image_topic``, at most
    ``debug_image_rate_hz`` times a second, at ``debug_jpeg_quality``.
    ``image_topic``, ``detections_topic`` and ``debug_image_topic`` are the first camera's
    (``stack.camera``); each further camera has them under ``camera_namespace``, its
    ``{camera}`` replaced by the camera's name (:func:`camera_topics`: the rear camera's
    images on ``/rear/camera/rgb/image_raw``, its detections on ``/rear/detections``), as a
    camera driver started in that namespace publishes them.
    ``depth_in`` takes each camera's depth image (``depth_topic``, ``sensor_msgs/Image``,
    16UC1 in mm or 32FC1 in m, aligned to the colour images) and its ``CameraInfo``
    (``depth_info_topic``) in as DepthFrames; each camera is then announced with ``depth``.
    ``detections_3d_out`` publishes the detections that carry depth columns as
    ``vision_msgs/Detection3DArray`` on ``detections_3d_topic``: in the camera's optical frame
    (the detections' frame id), or with ``detections_3d_frame`` (e.g. ``base_link``) in the
    robot's base frame by the camera's announced mounting.
    ``router_timeout_s`` bounds the wait for the router at start-up. A command on cmd_vel
    faster than ``max_command_linear`` (m/s) or ``max_command_angular`` (rad/s), the most
    the controller's own settings allow, is no command a sane controller sends: the bridge
    sends the robot zero instead and counts ``commands_out_of_range``.
    ``depth_scans_out`` publishes what the depth scan stage (services/depthscan) made, when
    the controller needs depth: each camera's virtual scan on ``<scan_topic>/virtual/<camera>``,
    what the depth memory holds round the robot on ``<scan_topic>/remembered`` and how far
    ahead the floor is known on ``<scan_topic>/known`` (sensor_msgs/LaserScan, robot frame).
    """

    router: Annotated[tuple[str, ...], Length(1, 16)] = ("tcp/127.0.0.1:7447",)
    listen: Annotated[tuple[str, ...], Length(0, 16)] = ("tcp/127.0.0.1:0",)
    domain_id: Annotated[int, Range(0, 232)] = 0  # the DDS domain ids that map to valid ports
    distro: RosDistro = RosDistro.JAZZY
    node: str = "zenoh_yolo_stack"
    namespace: str = "/"
    image_topic: str = "/camera/rgb/image_raw"
    image_format: ImageFormat = ImageFormat.RAW
    scan_topic: str = "/scan"
    detections_topic: str = "/detections"
    cmd_vel_topic: str = "/cmd_vel"
    twist_stamped: bool = False
    image_in: bool = True
    scan_in: bool = True
    detections_out: bool = True
    cmd_vel_out: bool = True
    debug_image_out: bool = False
    debug_image_topic: str = "/detections/image"
    debug_image_rate_hz: Annotated[float, Range(0.1, 100)] = 5.0
    debug_jpeg_quality: Annotated[int, Range(1, 100)] = 80
    camera_namespace: str = "/" + CAMERA_FIELD
    depth_in: bool = False
    depth_topic: str = "/camera/aligned_depth_to_color/image_raw"
    depth_info_topic: str = "/camera/aligned_depth_to_color/camera_info"
    detections_3d_out: bool = True
    detections_3d_topic: str = "/detections_3d"
    detections_3d_frame: str = ""
    depth_scans_out: bool = True
    router_timeout_s: Annotated[float, Range(0.1, 300)] = 5.0
    max_command_linear: Annotated[float, Range(0.01, 100)] = 5.0
    max_command_angular: Annotated[float, Range(0.01, 100)] = 10.0

    def __post_init__(self) -> None:
        check_bounds(self, "ros2", Ros2Settings)
        check_lengths(self, "ros2", Ros2Settings)
        enum_field(self, "distro", RosDistro, "ros2.distro")
        enum_field(self, "image_format", ImageFormat, "ros2.image_format")
        if not self.router or not all("/" in ep for ep in self.router):
            raise ConfigError(
                f"ros2.router must list endpoints like tcp/<host>:7447, got {list(self.router)}"
            )
        if not re.match(r"^[A-Za-z][A-Za-z0-9_]*$", self.node):
            raise ConfigError(f"ros2.node {self.node!r} is not a ROS 2 node name")
        if self.namespace != "/":
            _topic("namespace", self.namespace)
        topics = ("image_topic", "scan_topic", "detections_topic", "cmd_vel_topic")
        per_camera = ("depth_topic", "depth_info_topic", "detections_3d_topic")
        for name in (*topics, "debug_image_topic", *per_camera):
            _topic(name, getattr(self, name))
        if self.detections_3d_frame and not _FRAME_ID.match(self.detections_3d_frame):
            raise ConfigError(
                f"ros2.detections_3d_frame {self.detections_3d_frame!r} is not a frame id "
                "(e.g. base_link; empty: the camera's optical frame)"
            )
        if CAMERA_FIELD not in self.camera_namespace or not _TOPIC.match(
            self.camera_namespace.replace(CAMERA_FIELD, "camera")
        ):
            raise ConfigError(
                f"ros2.camera_namespace {self.camera_namespace!r} must be a ROS 2 namespace "
                f"holding {CAMERA_FIELD} (e.g. /{CAMERA_FIELD} or /robot/{CAMERA_FIELD})"
            )


@dataclass(frozen=True, slots=True)
class CameraTopics:
    """One camera's ROS 2 topics: its images, depth images and their CameraInfo in, its
    detections (2D and 3D) and debug images out."""

    image: str
    detections: str
    debug_image: str
    depth: str
    depth_info: str
    detections_3d: str


def camera_topics(settings: Ros2Settings, first: str, camera: str) -> CameraTopics:
    """The topics of ``camera``: the ``ros2`` table's own for the first camera (``first``,
    stack.camera), as a one-camera stack has always used them; each further camera's are those
    under ``ros2.camera_namespace`` with its name filled in (a relative topic stays
    relative)."""
    s = settings
    own = (s.image_topic, s.detections_topic, s.debug_image_topic, s.depth_topic,
           s.depth_info_topic, s.detections_3d_topic)  # fmt: skip
    if camera == first:
        return CameraTopics(*own)
    namespace = s.camera_namespace.replace(CAMERA_FIELD, camera).strip("/")

    def under(topic: str) -> str:
        inside = f"{namespace}/{topic.lstrip('/')}"
        return f"/{inside}" if topic.startswith("/") else inside

    return CameraTopics(*map(under, own))


def virtual_scan_topic(settings: Ros2Settings, camera: str) -> str:
    """The topic of ``camera``'s virtual scan (made from its depth images): beside the
    laser's, ``<ros2.scan_topic>/virtual/<camera>`` (``/scan/virtual/front``)."""
    return f"{settings.scan_topic.rstrip('/')}/virtual/{camera}"


def remembered_scan_topic(settings: Ros2Settings) -> str:
    """The depth memory's scan: ``<ros2.scan_topic>/remembered`` (``/scan/remembered``)."""
    return f"{settings.scan_topic.rstrip('/')}/remembered"


def known_floor_topic(settings: Ros2Settings) -> str:
    """How far ahead the floor is known: ``<ros2.scan_topic>/known`` (``/scan/known``)."""
    return f"{settings.scan_topic.rstrip('/')}/known"


def check_camera_topics(settings: Ros2Settings, cameras: Sequence[str]) -> None:
    """ConfigError unless every camera's topics (``cameras``: the first camera first) are ROS 2
    topic names and no two cameras, nor the scan and cmd_vel, share one."""
    seen = {settings.scan_topic: "ros2.scan_topic", settings.cmd_vel_topic: "ros2.cmd_vel_topic"}
    for camera in cameras:
        topics = camera_topics(settings, cameras[0], camera)
        for what, topic in (("image", topics.image), ("detections", topics.detections),
                            ("debug image", topics.debug_image), ("depth", topics.depth),
                            ("depth camera info", topics.depth_info),
                            ("3D detections", topics.detections_3d)):  # fmt: skip
            if not _TOPIC.match(topic):
                raise ConfigError(
                    f"ros2.camera_namespace {settings.camera_namespace!r} gives camera "
                    f"{camera!r} the {what} topic {topic!r}, not a ROS 2 topic name (a name "
                    "must start with a letter): rename the camera or change the namespace"
                )
            if topic in seen:
                raise ConfigError(
                    f"camera {camera!r}'s {what} topic {topic!r} is also {seen[topic]}: each "
                    "camera needs topics of its own (ros2.camera_namespace)"
                )
            seen[topic] = f"camera {camera!r}'s {what} topic"


#: The stack config's tables this service reads (stack/config.py's Config has each).
SETTINGS_TABLES = {"ros2": Ros2Settings}
