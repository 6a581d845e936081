"""Every message on the bus, as frozen dataclasses that encode and decode themselves.

The information matches the ROS 2 messages the lab used: ``std_msgs/Header`` (stamp, frame_id,
plus our seq and source), ``sensor_msgs/Image``, ``vision_msgs/Detection2DArray`` (class name,
score, box centre and size), ``geometry_msgs/Twist`` and ``sensor_msgs/LaserScan``.

Each field is declared once, here: its name and type are its wire format (common/fields.py),
(the messages without arrays, which the e-stop command needs, are declared in
common/control_messages.py, without numpy, and exported here with the rest),
and each message type has its own schema version, ``VERSION`` (common/codec.py). To add a field,
declare it with a default; bump the version only for a change older readers would misread.

Units: times are integer nanoseconds since the Unix epoch (``common.clock.wall_ns()``); image
coordinates are pixels of the image the detections were made on, origin top-left, x right,
y down; angles are radians, counter-clockwise positive (REP 103); ranges are metres.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar

import numpy as np
import numpy.typing as npt

from common.boxes import MAX_DETECTIONS, Boxes
from common.codec import Message
from common.control_messages import ControllerStatus as ControllerStatus
from common.control_messages import EStop as EStop
from common.control_messages import Header as Header
from common.field_types import Dim, Inline, NonNegativeInt, Shape
from common.limits import MAX_IMAGE_SIDE as MAX_IMAGE_SIDE

# ControllerStatus, EStop and Header are declared without numpy, for the e-stop command, and
# exported here with every other message.

# A class name (COCO's longest is 14 characters, LVIS's about 40) and a model or backend name:
# longer ones are refused where they enter, so that no receiver keeps megabytes of names.
MAX_NAME_CHARS = 128
# A velocity command's magnitude, m/s or rad/s: no base goes near it; 1e308 is garbage.
MAX_COMMAND = 100.0
MAX_SCAN_RAYS = 100_000

FRAME_ENCODINGS: dict[str, int] = {"bgr8": 3, "rgb8": 3, "mono8": 1, "jpeg": 0}

# The counts that size a message's arrays; each travels on the wire as "n", and is checked
# against its bounds before any array is read (Detections' is common.boxes.N_DETECTIONS).
N_RAYS = Dim("n", 1, MAX_SCAN_RAYS)
N_TARGETS = Dim("n", 0, MAX_DETECTIONS)


@dataclass(frozen=True, slots=True, kw_only=True)
class Frame(Message):
    """One camera image. ``data`` is row-major pixels for raw encodings, a JPEG file for jpeg."""

    TAG: ClassVar[str] = "Frame"
    VERSION: ClassVar[int] = 1
    header: Header
    encoding: str
    width: int
    height: int
    data: bytes

    def __post_init__(self) -> None:
        if self.encoding not in FRAME_ENCODINGS:
            raise ValueError(f"unknown encoding {self.encoding!r}")
        channels = FRAME_ENCODINGS[self.encoding]
        _check_pixels("image", self.encoding, self.width, self.height, channels, self.data)
        if not channels and not self.data:
            raise ValueError("empty jpeg")


def _check_pixels(
    what: str, encoding: str, width: int, height: int, size: int, data: bytes
) -> None:
    """A raw image's size within bounds and its ``data`` exactly ``width*height*size`` bytes
    (``size`` 0: a compressed image, any length)."""
    if not (0 < width <= MAX_IMAGE_SIDE and 0 < height <= MAX_IMAGE_SIDE):
        raise ValueError(f"absurd {what} size {width}x{height}")
    if size and len(data) != width * height * size:
        raise ValueError(
            f"{encoding} {width}x{height} needs {width * height * size} bytes, got {len(data)}"
        )


#: Depth encodings, as ``sensor_msgs/Image``'s: bytes per pixel. ``16UC1`` is millimetres (0: no
#: reading), ``32FC1`` metres (0, NaN or inf: no reading); both little-endian.
DEPTH_ENCODINGS: dict[str, int] = {"16UC1": 2, "32FC1": 4}
#: The longest range a depth image may state (m): beyond every RGB-D sensor's.
MAX_DEPTH_RANGE_M = 1000.0


@dataclass(frozen=True, slots=True, kw_only=True)
class DepthFrame(Message):
    """One depth image, aligned to its camera's colour frames: ``sensor_msgs/Image`` (16UC1 or
    32FC1) with the pinhole part of its ``sensor_msgs/CameraInfo``.

    Pixel (u, v) of the depth image sees what pixel (u * colour_width / width, v *
    colour_height / height) of the colour frame sees (the source aligns depth to colour), so
    one set of intrinsics, ``fx``, ``fy``, ``cx``, ``cy`` in pixels of *this* image, serves
    both. The optical frame is REP 103's camera optical frame: x right, y down, z forward; a
    reading is the z of what the pixel sees. ``header.stamp_ns`` is the capture time: the
    detector pairs a colour frame with the depth image of its camera whose stamp is nearest,
    within ``detector.depth_pair_tolerance_ms``. ``range_min_m``/``range_max_m``: the
    sensor's valid range (readings outside it are no readings); 0 for ``range_max_m`` when
    the source does not state one. ``header.frame_id`` is the colour frames'.
    """

    TAG: ClassVar[str] = "DepthFrame"
    VERSION: ClassVar[int] = 1
    header: Header
    encoding: str
    width: int
    height: int
    data: bytes
    fx: float
    fy: float
    cx: float
    cy: float
    range_min_m: float = 0.0
    range_max_m: float = 0.0

    def __post_init__(self) -> None:
        if self.encoding not in DEPTH_ENCODINGS:
            raise ValueError(f"unknown depth encoding {self.encoding!r} (16UC1 or 32FC1)")
        pixel_bytes = DEPTH_ENCODINGS[self.encoding]
        _check_pixels("depth image", self.encoding, self.width, self.height, pixel_bytes, self.data)
        for what, f in (("fx", self.fx), ("fy", self.fy)):
            if not (math.isfinite(f) and 0 < f < 1e6):
                raise ValueError(f"focal length {what} {f} is outside (0, 1e6) pixels")
        for what, c, side in (("cx", self.cx, self.width), ("cy", self.cy, self.height)):
            if not (math.isfinite(c) and -side <= c <= 2 * side):
                raise ValueError(f"principal point {what} {c} is far outside the image")
        if not (
            math.isfinite(self.range_min_m)
            and math.isfinite(self.range_max_m)
            and 0 <= self.range_min_m <= MAX_DEPTH_RANGE_M
            and 0 <= self.range_max_m <= MAX_DEPTH_RANGE_M
            and (self.range_max_m == 0 or self.range_min_m < self.range_max_m)
        ):
            raise ValueError(
                f"range {self.range_min_m}..{self.range_max_m} m is not 0 <= min < max "
                f"<= {MAX_DEPTH_RANGE_M:g} (max 0: not stated)"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class Detections(Message):
    """The detections of one frame: ``vision_msgs/Detection2DArray`` as a struct of arrays.

    ``header`` is the frame's header, unchanged, so latency is measured from the capture stamp.
    ``boxes`` (common/boxes.py) are in pixels of the ``image_width`` x ``image_height`` image,
    with ``track_ids`` -1 where no tracker has assigned an id, or None; ``class_names`` names
    each row. The boxes travel inline: ``xyxy``, ``scores``, ``class_ids``, ``track_ids``,
    ``columns`` (named per-detection arrays, e.g. ``distance_m``) and their count ``n`` are
    keys of the message body itself (docs/messages.md).
    ``timing_ms`` holds the detector's stages (preprocess, inference, postprocess);
    ``received_ns`` and ``published_ns`` are when the detector took and sent the frame.
    ``worker``: the detector worker that made them (its pool name; "" from a writer before
    it existed): the pool judges each member by its own detections (common/pool_delivery.py).
    """

    TAG: ClassVar[str] = "Detections"
    VERSION: ClassVar[int] = 1
    header: Header
    image_width: int
    image_height: int
    boxes: Annotated[Boxes, Inline()]
    class_names: tuple[str, ...]
    timing_ms: dict[str, float] = field(default_factory=dict)
    model: str = ""
    backend: str = ""
    received_ns: NonNegativeInt = 0
    published_ns: NonNegativeInt = 0
    worker: str = ""

    def __post_init__(self) -> None:
        n = len(self.boxes)
        if n > MAX_DETECTIONS:
            raise ValueError(f"{n} detections is over the limit of {MAX_DETECTIONS}")
        if not (0 < self.image_width <= MAX_IMAGE_SIDE and 0 < self.image_height <= MAX_IMAGE_SIDE):
            raise ValueError(f"absurd image size {self.image_width}x{self.image_height}")
        if len(self.class_names) != n:
            raise ValueError(f"class_names must have {n} entries, got {len(self.class_names)}")
        longest = max((len(name) for name in self.class_names), default=0)
        if longest > MAX_NAME_CHARS:
            raise ValueError(f"a class name of {longest} characters (at most {MAX_NAME_CHARS})")
        if max(len(self.model), len(self.backend), len(self.worker)) > 2 * MAX_NAME_CHARS:
            raise ValueError(f"model, backend or worker name over {2 * MAX_NAME_CHARS} characters")

    def __len__(self) -> int:
        return len(self.boxes)

    @property
    def centers(self) -> npt.NDArray[np.float32]:
        """Box centres (n, 2) in pixels, as ``BoundingBox2D.center``."""
        xyxy = self.boxes.xyxy
        return ((xyxy[:, :2] + xyxy[:, 2:]) / 2).astype(np.float32)

    @property
    def sizes(self) -> npt.NDArray[np.float32]:
        """Box sizes (n, 2) width and height in pixels, as ``BoundingBox2D.size_x/size_y``."""
        xyxy = self.boxes.xyxy
        return (xyxy[:, 2:] - xyxy[:, :2]).astype(np.float32)

    def _wire_extras(self) -> dict[str, Any]:
        # (n, 4) float32 cx, cy, w, h for readers in other languages; decode ignores it.
        center_size = np.hstack([self.centers, self.sizes])
        return {"center_size": np.ascontiguousarray(center_size, "<f4").tobytes()}


@dataclass(frozen=True, slots=True, kw_only=True)
class Twist(Message):
    """A velocity command, as ``geometry_msgs/Twist``: m/s and rad/s in the robot's base frame.

    ``input_stamp_ns`` is the capture stamp of the frame whose detections this command reacts
    to (0 when it reacts to none, e.g. a stop), so capture-to-command latency can be measured.
    """

    TAG: ClassVar[str] = "Twist"
    VERSION: ClassVar[int] = 1
    header: Header
    linear: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular: tuple[float, float, float] = (0.0, 0.0, 0.0)
    input_stamp_ns: NonNegativeInt = 0

    def __post_init__(self) -> None:
        # A NaN reaching a motor driver that does not check is a runaway: refuse to build one.
        if not all(math.isfinite(v) for v in (*self.linear, *self.angular)):
            raise ValueError(f"velocities must be finite, got {self.linear} {self.angular}")
        if any(abs(v) > MAX_COMMAND for v in (*self.linear, *self.angular)):
            raise ValueError(f"velocities over {MAX_COMMAND:g} are garbage, got {self.linear} "
                             f"{self.angular}")  # fmt: skip

    @property
    def is_zero(self) -> bool:
        return not any(self.linear) and not any(self.angular)


@dataclass(frozen=True, slots=True, kw_only=True)
class LaserScan(Message):
    """A planar scan, as ``sensor_msgs/LaserScan``: ray i points at angle_min + i*increment.

    ``ranges`` is (n,) float32 in metres; inf means nothing within range_max, NaN an invalid ray.
    """

    TAG: ClassVar[str] = "LaserScan"
    VERSION: ClassVar[int] = 1
    header: Header
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: Annotated[npt.NDArray[np.float32], Shape(N_RAYS)]

    def __post_init__(self) -> None:
        if not 0 < len(self.ranges) <= MAX_SCAN_RAYS:
            raise ValueError(f"a scan needs 1..{MAX_SCAN_RAYS} rays, got {len(self.ranges)}")
        if not (np.isfinite(self.angle_min) and np.isfinite(self.angle_increment)):
            raise ValueError("angles must be finite")
        if not 0 <= self.range_min < self.range_max:
            raise ValueError(f"range_min {self.range_min} must be below range_max {self.range_max}")

    @property
    def angles(self) -> npt.NDArray[np.float64]:
        """The angle of each ray in radians, (n,) float64."""
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges), dtype=np.float64)


@dataclass(frozen=True, slots=True, kw_only=True)
class GroundTruth(Message):
    """The simulator's truth: the robot's pose and every target's position, in the world frame.

    ``sim_time_s`` is the scenario clock, which starts once the detector and controller are up.
    ``robot`` is (x, y, theta) in metres and radians; ``targets_xy`` is (n, 2) float64 metres;
    ``target_names`` the class of each target (e.g. "person") and ``target_ids`` its scenario
    id, so a run can be scored against what really happened. ``obstacles`` is (m, 3) float64,
    each round obstacle's centre x, y and radius in metres (the live view draws them).
    """

    TAG: ClassVar[str] = "GroundTruth"
    VERSION: ClassVar[int] = 1
    header: Header
    sim_time_s: float
    robot: tuple[float, float, float]
    robot_velocity: tuple[float, float] = (0.0, 0.0)
    targets_xy: Annotated[npt.NDArray[np.float64], Shape(N_TARGETS, 2)] = field(
        default_factory=lambda: np.zeros((0, 2))
    )
    target_names: tuple[str, ...] = ()
    target_ids: tuple[str, ...] = ()
    # Absent from truths written before it existed: no obstacles. The row count comes from the
    # byte length (no count of its own on the wire, so older payloads still decode).
    obstacles: Annotated[npt.NDArray[np.float64], Shape(-1, 3)] = field(
        default_factory=lambda: np.zeros((0, 3))
    )

    def __post_init__(self) -> None:
        n = len(self.target_names)
        if self.targets_xy.shape != (n, 2) or len(self.target_ids) != n:
            raise ValueError(f"targets_xy must be ({n}, 2) with {n} ids")
        if self.obstacles.ndim != 2 or self.obstacles.shape[1] != 3:
            raise ValueError(f"obstacles must be (m, 3) x, y, radius, got {self.obstacles.shape}")
        if len(self.obstacles) > MAX_DETECTIONS:
            raise ValueError(f"{len(self.obstacles)} obstacles is over {MAX_DETECTIONS}")


@dataclass(frozen=True, slots=True, kw_only=True)
class ServiceCounters(Message):
    """A service's own counters (frames in, dropped, bad input ...), published periodically."""

    TAG: ClassVar[str] = "ServiceCounters"
    VERSION: ClassVar[int] = 1
    header: Header
    service: str
    counters: dict[str, int]


@dataclass(frozen=True, slots=True, kw_only=True)
class MetricsSnapshot(Message):
    """The metrics service's view of the stack over its sliding window.

    ``latency_ms`` maps a stage name (e.g. "capture_to_detections", "end_to_end") to its
    percentiles ({"p50", "p95", "p99", "mean", "count"}). ``counters`` maps
    "<service>.<counter>" to a count, bad input included.
    """

    TAG: ClassVar[str] = "MetricsSnapshot"
    VERSION: ClassVar[int] = 1
    header: Header
    window_s: float
    fps: float
    frames: NonNegativeInt
    detections: NonNegativeInt
    detections_per_frame: float
    dropped_frames: NonNegativeInt
    latency_ms: dict[str, dict[str, float]]
    counters: dict[str, int]
    class_counts: dict[str, int] = field(default_factory=dict)

    def to_json_dict(self) -> dict[str, Any]:
        """The snapshot as plain JSON-able data, the answer to a metrics query."""
        return {
            "stamp_ns": self.header.stamp_ns,
            "window_s": self.window_s,
            "fps": self.fps,
            "frames": self.frames,
            "detections": self.detections,
            "detections_per_frame": self.detections_per_frame,
            "dropped_frames": self.dropped_frames,
            "latency_ms": self.latency_ms,
            "counters": self.counters,
            "class_counts": self.class_counts,
        }

    def _wire_extras(self) -> dict[str, Any]:
        # The body has always been the JSON answer plus the header, so it carries the header's
        # stamp_ns at the top level too; decode ignores it.
        return {"stamp_ns": self.header.stamp_ns}


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraAnnouncement(Message):
    """A camera as its source describes it on the bus while it publishes the camera's frames
    (common/announce.py carries it in a liveliness token's key: it lives exactly as long as
    the source does). Pool workers, the controller and the metrics service take the camera set
    and each camera's weight and geometry from these, not from their own config.

    ``width``/``height``: the frames' size, 0 while the source does not know it yet (a camera
    that keeps its device's size, before the first frame). ``rate_hz``: the frames per second
    it sends. ``mount_yaw_deg``: where it looks on the robot, counter-clockwise from forward;
    ``hfov_deg``: its horizontal field of view. ``frame_id``: its frames' header frame id.
    ``source``: what announces it (``camera``, ``sim``, ``ros2``, ``play``). ``depth``: the
    source also publishes aligned depth images of it (DepthFrame, ``Keys.depth``).
    ``mount_height_m``: its optical centre's height above the floor (0: not known; a virtual
    scan from its depth needs it, to take the floor out); ``mount_x_m``/``mount_y_m``: where
    it stands on the robot, forward and left of the base's centre (REP 103). The camera is
    taken to look level (no pitch or roll). ``zid``: the Zenoh session id of the announcer,
    which publishes the camera's depth from that same session: the controller takes depth
    only from samples whose publisher is in it (docs/security.md, "Depth from the announced
    source only"); "" from an announcer older than the field, whose depth is then taken from
    any publisher, as before."""

    TAG: ClassVar[str] = "CameraAnnouncement"
    VERSION: ClassVar[int] = 1
    camera: str
    width: int = 0
    height: int = 0
    rate_hz: float
    mount_yaw_deg: float = 0.0
    hfov_deg: float = 60.0
    frame_id: str = ""
    source: str = ""
    depth: bool = False
    mount_height_m: float = 0.0
    mount_x_m: float = 0.0
    mount_y_m: float = 0.0
    zid: str = ""

    def __post_init__(self) -> None:
        _check_announced_name("camera", self.camera)
        if self.zid:
            _check_announced_name("zid", self.zid)
        if not (math.isfinite(self.mount_height_m) and 0 <= self.mount_height_m <= 10):
            raise ValueError(f"mount_height_m {self.mount_height_m} is outside [0, 10]")
        for what, offset in (("mount_x_m", self.mount_x_m), ("mount_y_m", self.mount_y_m)):
            if not (math.isfinite(offset) and abs(offset) <= 10):
                raise ValueError(f"{what} {offset} is outside [-10, 10]")
        for what, side in (("width", self.width), ("height", self.height)):
            if not 0 <= side <= MAX_IMAGE_SIDE:
                raise ValueError(f"{what} {side} is outside 0..{MAX_IMAGE_SIDE}")
        if (self.width == 0) != (self.height == 0):
            raise ValueError(f"size {self.width}x{self.height}: both known or neither")
        if not (math.isfinite(self.rate_hz) and 0 < self.rate_hz <= MAX_ANNOUNCED_RATE_HZ):
            raise ValueError(f"rate_hz {self.rate_hz} is outside (0, {MAX_ANNOUNCED_RATE_HZ}]")
        if not (math.isfinite(self.mount_yaw_deg) and -180 <= self.mount_yaw_deg <= 180):
            raise ValueError(f"mount_yaw_deg {self.mount_yaw_deg} is outside [-180, 180]")
        if not (math.isfinite(self.hfov_deg) and 0 < self.hfov_deg < 180):
            raise ValueError(f"hfov_deg {self.hfov_deg} is outside (0, 180)")
        for what, text in (("frame_id", self.frame_id), ("source", self.source)):
            if len(text) > MAX_NAME_CHARS:
                raise ValueError(f"{what} of {len(text)} characters (at most {MAX_NAME_CHARS})")


@dataclass(frozen=True, slots=True, kw_only=True)
class WorkerAnnouncement(Message):
    """A detector worker as it describes itself to the pool while it is in it (common/
    announce.py: in a liveliness token's key). ``capacity_hz``: the frames per second it can
    detect, measured at start and kept current, at its ``input_size``, ``backend`` and batch
    (``max_batch``, the round size it runs); the pool gives each worker a share of the
    cameras' frame rate in proportion to it. ``prefixes``: the robots' key prefixes whose
    cameras it serves (empty: the pool's own prefix only). ``seq`` grows with each
    re-announcement of one worker process (a new capacity): of two tokens alive for one name,
    the higher is current."""

    TAG: ClassVar[str] = "WorkerAnnouncement"
    VERSION: ClassVar[int] = 1
    worker: str
    capacity_hz: float
    input_size: int = 0
    backend: str = ""
    max_batch: int = 1
    prefixes: tuple[str, ...] = ()
    seq: int = 0

    def __post_init__(self) -> None:
        _check_announced_name("worker", self.worker)
        if not (math.isfinite(self.capacity_hz) and 0 < self.capacity_hz <= MAX_CAPACITY_HZ):
            raise ValueError(f"capacity_hz {self.capacity_hz} is outside (0, {MAX_CAPACITY_HZ}]")
        if not 0 <= self.input_size <= MAX_IMAGE_SIDE:
            raise ValueError(f"input_size {self.input_size} is outside 0..{MAX_IMAGE_SIDE}")
        if not 1 <= self.max_batch <= 1024:
            raise ValueError(f"max_batch {self.max_batch} is outside 1..1024")
        if not 0 <= self.seq < 2**53:
            raise ValueError(f"seq {self.seq} is outside 0..2**53")
        if len(self.backend) > MAX_NAME_CHARS:
            raise ValueError(f"backend of {len(self.backend)} characters (over {MAX_NAME_CHARS})")
        if len(self.prefixes) > MAX_ANNOUNCED_PREFIXES:
            raise ValueError(f"{len(self.prefixes)} prefixes (at most {MAX_ANNOUNCED_PREFIXES})")
        for prefix in self.prefixes:
            if not all(_ANNOUNCED_NAME.fullmatch(chunk) for chunk in prefix.split("/")):
                raise ValueError(f"prefix {prefix[:80]!r} is not a key prefix")


#: The highest frame rate a camera may announce, and the highest capacity a worker may: beyond
#: any real sensor or accelerator, so that one liar cannot take every share of the pool.
MAX_ANNOUNCED_RATE_HZ = 1000.0
MAX_CAPACITY_HZ = 100_000.0
MAX_ANNOUNCED_PREFIXES = 64  # robots one worker serves
_ANNOUNCED_NAME = re.compile(r"[A-Za-z0-9_.\-]{1,64}")


def _check_announced_name(what: str, name: str) -> None:
    if not _ANNOUNCED_NAME.fullmatch(name):
        raise ValueError(f"{what} name {name[:80]!r} is not 1..64 of A-Z a-z 0-9 _ . -")
