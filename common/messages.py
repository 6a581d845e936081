"""Every message on the bus, as frozen dataclasses that encode and decode themselves.

The information matches the ROS 2 messages the lab used: ``std_msgs/Header`` (stamp, frame_id,
plus our seq and source), ``sensor_msgs/Image``, ``vision_msgs/Detection2DArray`` (class name,
score, box centre and size), ``geometry_msgs/Twist`` and ``sensor_msgs/LaserScan``.

Units: times are integer nanoseconds since the Unix epoch (``time.time_ns()``); image
coordinates are pixels of the image the detections were made on, origin top-left, x right,
y down; angles are radians, counter-clockwise positive (REP 103); ranges are metres.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar, Self

import numpy as np
import numpy.typing as npt

from common.codec import Body, array_bytes, pack, unpack
from common.errors import DecodeError

# Limits that no real camera reaches; anything above is garbage, not a frame.
MAX_IMAGE_SIDE = 16384
MAX_DETECTIONS = 10000
MAX_SCAN_RAYS = 100_000

FRAME_ENCODINGS: dict[str, int] = {"bgr8": 3, "rgb8": 3, "mono8": 1, "jpeg": 0}


def now_ns() -> int:
    """Wall-clock time in ns, the stamp used across processes."""
    return time.time_ns()


@dataclass(frozen=True, slots=True, kw_only=True)
class Header:
    """Who produced a message, when the data it describes was captured, and its sequence.

    ``stamp_ns`` is wall-clock time. ``mono_ns`` is the same instant on the producer's
    monotonic clock and ``boot_id`` names that clock (the host's boot); 0 and "" when unknown.
    A receiver on the same boot judges age on both clocks (common/freshness.py).
    """

    stamp_ns: int
    frame_id: str
    seq: int
    source: str
    mono_ns: int = 0
    boot_id: str = ""

    def to_wire(self) -> dict[str, Any]:
        return {
            "stamp_ns": self.stamp_ns,
            "frame_id": self.frame_id,
            "seq": self.seq,
            "source": self.source,
            "mono_ns": self.mono_ns,
            "boot_id": self.boot_id,
        }

    @classmethod
    def from_wire(cls, b: Body) -> Header:
        return cls(
            stamp_ns=b.get_int("stamp_ns", 0),
            frame_id=b.get_str("frame_id"),
            seq=b.get_int("seq", 0),
            source=b.get_str("source"),
            # Absent from headers written before these fields existed: unknown.
            mono_ns=b.get_int("mono_ns", 0) if "mono_ns" in b.fields() else 0,
            boot_id=b.get_str("boot_id") if "boot_id" in b.fields() else "",
        )


class _Message:
    """Shared encode/decode plumbing; subclasses provide TAG, _body and _from_body."""

    TAG: ClassVar[str]

    def _body(self) -> dict[str, Any]:
        raise NotImplementedError

    @classmethod
    def _from_body(cls, b: Body) -> Self:
        raise NotImplementedError

    def encode(self) -> bytes:
        return pack(self.TAG, self._body())

    @classmethod
    def decode(cls, payload: bytes | bytearray | memoryview) -> Self:
        """Decode ``payload`` or raise DecodeError; never any other exception."""
        body = Body(cls.TAG, unpack(payload, cls.TAG))
        try:
            return cls._from_body(body)
        except DecodeError:
            raise
        except (ValueError, TypeError) as exc:  # a __post_init__ check on decoded values
            raise DecodeError(f"{cls.TAG}: {exc}") from exc


@dataclass(frozen=True, slots=True, kw_only=True)
class Frame(_Message):
    """One camera image. ``data`` is row-major pixels for raw encodings, a JPEG file for jpeg."""

    TAG: ClassVar[str] = "Frame"
    header: Header
    encoding: str
    width: int
    height: int
    data: bytes

    def __post_init__(self) -> None:
        if self.encoding not in FRAME_ENCODINGS:
            raise ValueError(f"unknown encoding {self.encoding!r}")
        if not (0 < self.width <= MAX_IMAGE_SIDE and 0 < self.height <= MAX_IMAGE_SIDE):
            raise ValueError(f"absurd image size {self.width}x{self.height}")
        channels = FRAME_ENCODINGS[self.encoding]
        if channels and len(self.data) != self.width * self.height * channels:
            raise ValueError(
                f"{self.encoding} {self.width}x{self.height} needs "
                f"{self.width * self.height * channels} bytes, got {len(self.data)}"
            )
        if not channels and not self.data:
            raise ValueError("empty jpeg")

    def _body(self) -> dict[str, Any]:
        return {
            "header": self.header.to_wire(),
            "encoding": self.encoding,
            "width": self.width,
            "height": self.height,
            "data": self.data,
        }

    @classmethod
    def _from_body(cls, b: Body) -> Frame:
        return cls(
            header=Header.from_wire(b.get_map("header")),
            encoding=b.get_str("encoding"),
            width=b.get_int("width"),
            height=b.get_int("height"),
            data=b.get_bytes("data"),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class Detections(_Message):
    """The detections of one frame: ``vision_msgs/Detection2DArray`` as a struct of arrays.

    ``header`` is the frame's header, unchanged, so latency is measured from the capture stamp.
    Boxes are ``xyxy`` (n, 4) float32 in pixels of the ``image_width`` x ``image_height`` image.
    ``track_ids`` is (n,) int32 with -1 where no tracker has assigned an id, or None.
    ``timing_ms`` holds the detector's stages (preprocess, inference, postprocess);
    ``received_ns`` and ``published_ns`` are when the detector took and sent the frame.
    """

    TAG: ClassVar[str] = "Detections"
    header: Header
    image_width: int
    image_height: int
    class_ids: npt.NDArray[np.int32]
    class_names: tuple[str, ...]
    scores: npt.NDArray[np.float32]
    xyxy: npt.NDArray[np.float32]
    track_ids: npt.NDArray[np.int32] | None = None
    timing_ms: dict[str, float] = field(default_factory=dict)
    model: str = ""
    backend: str = ""
    received_ns: int = 0
    published_ns: int = 0

    def __post_init__(self) -> None:
        n = len(self.class_ids)
        if n > MAX_DETECTIONS:
            raise ValueError(f"{n} detections is over the limit of {MAX_DETECTIONS}")
        if not (0 < self.image_width <= MAX_IMAGE_SIDE and 0 < self.image_height <= MAX_IMAGE_SIDE):
            raise ValueError(f"absurd image size {self.image_width}x{self.image_height}")
        if self.xyxy.shape != (n, 4):
            raise ValueError(f"xyxy must be ({n}, 4), got {self.xyxy.shape}")
        if self.scores.shape != (n,) or len(self.class_names) != n:
            raise ValueError(f"scores and class_names must have {n} entries")
        if self.track_ids is not None and self.track_ids.shape != (n,):
            raise ValueError(f"track_ids must be ({n},), got {self.track_ids.shape}")
        if not (np.isfinite(self.xyxy).all() and np.isfinite(self.scores).all()):
            raise ValueError("boxes and scores must be finite")
        if ((self.xyxy[:, 2] < self.xyxy[:, 0]) | (self.xyxy[:, 3] < self.xyxy[:, 1])).any():
            raise ValueError("boxes must have x2 >= x1 and y2 >= y1")

    def __len__(self) -> int:
        return len(self.class_ids)

    @property
    def centers(self) -> npt.NDArray[np.float32]:
        """Box centres (n, 2) in pixels, as ``BoundingBox2D.center``."""
        return ((self.xyxy[:, :2] + self.xyxy[:, 2:]) / 2).astype(np.float32)

    @property
    def sizes(self) -> npt.NDArray[np.float32]:
        """Box sizes (n, 2) width and height in pixels, as ``BoundingBox2D.size_x/size_y``."""
        return (self.xyxy[:, 2:] - self.xyxy[:, :2]).astype(np.float32)

    def _body(self) -> dict[str, Any]:
        # centre/size go on the wire too, for readers in other languages; decode ignores them.
        return {
            "header": self.header.to_wire(),
            "image_width": self.image_width,
            "image_height": self.image_height,
            "n": len(self),
            "class_ids": array_bytes(self.class_ids, np.int32),
            "class_names": list(self.class_names),
            "scores": array_bytes(self.scores, np.float32),
            "xyxy": array_bytes(self.xyxy, np.float32),
            "center_size": array_bytes(np.hstack([self.centers, self.sizes]), np.float32),
            "track_ids": None if self.track_ids is None else array_bytes(self.track_ids, np.int32),
            "timing_ms": self.timing_ms,
            "model": self.model,
            "backend": self.backend,
            "received_ns": self.received_ns,
            "published_ns": self.published_ns,
        }

    @classmethod
    def _from_body(cls, b: Body) -> Detections:
        n = b.get_int("n", 0, MAX_DETECTIONS)
        track = None if b.is_null("track_ids") else b.array("track_ids", np.int32, (n,))
        return cls(
            header=Header.from_wire(b.get_map("header")),
            image_width=b.get_int("image_width"),
            image_height=b.get_int("image_height"),
            class_ids=b.array("class_ids", np.int32, (n,)),
            class_names=b.str_list("class_names"),
            scores=b.array("scores", np.float32, (n,)),
            xyxy=b.array("xyxy", np.float32, (n, 4)),
            track_ids=track,
            timing_ms=b.float_map("timing_ms"),
            model=b.get_str("model"),
            backend=b.get_str("backend"),
            received_ns=b.get_int("received_ns", 0),
            published_ns=b.get_int("published_ns", 0),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class Twist(_Message):
    """A velocity command, as ``geometry_msgs/Twist``: m/s and rad/s in the robot's base frame.

    ``input_stamp_ns`` is the capture stamp of the frame whose detections this command reacts
    to (0 when it reacts to none, e.g. a stop), so capture-to-command latency can be measured.
    """

    TAG: ClassVar[str] = "Twist"
    header: Header
    linear: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular: tuple[float, float, float] = (0.0, 0.0, 0.0)
    input_stamp_ns: int = 0

    def __post_init__(self) -> None:
        # A NaN reaching a motor driver that does not check is a runaway: refuse to build one.
        if not all(math.isfinite(v) for v in (*self.linear, *self.angular)):
            raise ValueError(f"velocities must be finite, got {self.linear} {self.angular}")

    @property
    def is_zero(self) -> bool:
        return not any(self.linear) and not any(self.angular)

    def _body(self) -> dict[str, Any]:
        return {
            "header": self.header.to_wire(),
            "linear": list(self.linear),
            "angular": list(self.angular),
            "input_stamp_ns": self.input_stamp_ns,
        }

    @classmethod
    def _from_body(cls, b: Body) -> Twist:
        return cls(
            header=Header.from_wire(b.get_map("header")),
            linear=_vec3(b, "linear"),
            angular=_vec3(b, "angular"),
            input_stamp_ns=b.get_int("input_stamp_ns", 0),
        )


def _vec3(b: Body, key: str) -> tuple[float, float, float]:
    v = b.floats(key)
    if len(v) != 3 or not all(np.isfinite(v)):
        raise DecodeError(f"{b.tag}.{key}: expected 3 finite numbers, got {v}")
    return (v[0], v[1], v[2])


@dataclass(frozen=True, slots=True, kw_only=True)
class LaserScan(_Message):
    """A planar scan, as ``sensor_msgs/LaserScan``: ray i points at angle_min + i*increment.

    ``ranges`` is (n,) float32 in metres; inf means nothing within range_max, NaN an invalid ray.
    """

    TAG: ClassVar[str] = "LaserScan"
    header: Header
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: npt.NDArray[np.float32]

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

    def _body(self) -> dict[str, Any]:
        return {
            "header": self.header.to_wire(),
            "angle_min": self.angle_min,
            "angle_increment": self.angle_increment,
            "range_min": self.range_min,
            "range_max": self.range_max,
            "n": len(self.ranges),
            "ranges": array_bytes(self.ranges, np.float32),
        }

    @classmethod
    def _from_body(cls, b: Body) -> LaserScan:
        n = b.get_int("n", 1, MAX_SCAN_RAYS)
        return cls(
            header=Header.from_wire(b.get_map("header")),
            angle_min=b.get_float("angle_min"),
            angle_increment=b.get_float("angle_increment"),
            range_min=b.get_float("range_min"),
            range_max=b.get_float("range_max"),
            ranges=b.array("ranges", np.float32, (n,)),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class ControllerStatus(_Message):
    """What the controller is doing and why: mode, target and state (e.g. "following")."""

    TAG: ClassVar[str] = "ControllerStatus"
    header: Header
    mode: str
    target: str
    state: str
    reason: str = ""
    track_id: int = -1

    def _body(self) -> dict[str, Any]:
        return {
            "header": self.header.to_wire(),
            "mode": self.mode,
            "target": self.target,
            "state": self.state,
            "reason": self.reason,
            "track_id": self.track_id,
        }

    @classmethod
    def _from_body(cls, b: Body) -> ControllerStatus:
        return cls(
            header=Header.from_wire(b.get_map("header")),
            mode=b.get_str("mode"),
            target=b.get_str("target"),
            state=b.get_str("state"),
            reason=b.get_str("reason"),
            track_id=b.get_int("track_id"),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class GroundTruth(_Message):
    """The simulator's truth: the robot's pose and every target's position, in the world frame.

    ``sim_time_s`` is the scenario clock, which starts once the detector and controller are up.
    ``robot`` is (x, y, theta) in metres and radians; ``targets_xy`` is (n, 2) float64 metres;
    ``target_names`` the class of each target (e.g. "person") and ``target_ids`` its scenario
    id, so a run can be scored against what really happened.
    """

    TAG: ClassVar[str] = "GroundTruth"
    header: Header
    sim_time_s: float
    robot: tuple[float, float, float]
    robot_velocity: tuple[float, float] = (0.0, 0.0)
    targets_xy: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 2)))
    target_names: tuple[str, ...] = ()
    target_ids: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.target_names)
        if self.targets_xy.shape != (n, 2) or len(self.target_ids) != n:
            raise ValueError(f"targets_xy must be ({n}, 2) with {n} ids")

    def _body(self) -> dict[str, Any]:
        return {
            "header": self.header.to_wire(),
            "sim_time_s": self.sim_time_s,
            "robot": list(self.robot),
            "robot_velocity": list(self.robot_velocity),
            "n": len(self.target_names),
            "targets_xy": array_bytes(self.targets_xy, np.float64),
            "target_names": list(self.target_names),
            "target_ids": list(self.target_ids),
        }

    @classmethod
    def _from_body(cls, b: Body) -> GroundTruth:
        n = b.get_int("n", 0, MAX_DETECTIONS)
        vel = b.floats("robot_velocity")
        if len(vel) != 2:
            raise DecodeError(f"{b.tag}.robot_velocity: expected 2 numbers")
        return cls(
            header=Header.from_wire(b.get_map("header")),
            sim_time_s=b.get_float("sim_time_s"),
            robot=_vec3(b, "robot"),
            robot_velocity=(vel[0], vel[1]),
            targets_xy=b.array("targets_xy", np.float64, (n, 2)),
            target_names=b.str_list("target_names"),
            target_ids=b.str_list("target_ids"),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class EStop(_Message):
    """The emergency stop: ``engaged`` latches zero velocity until an EStop with False."""

    TAG: ClassVar[str] = "EStop"
    header: Header
    engaged: bool
    reason: str = ""

    def _body(self) -> dict[str, Any]:
        return {"header": self.header.to_wire(), "engaged": self.engaged, "reason": self.reason}

    @classmethod
    def _from_body(cls, b: Body) -> EStop:
        return cls(
            header=Header.from_wire(b.get_map("header")),
            engaged=b.get_bool("engaged"),
            reason=b.get_str("reason"),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class ServiceCounters(_Message):
    """A service's own counters (frames in, dropped, bad input ...), published periodically."""

    TAG: ClassVar[str] = "ServiceCounters"
    header: Header
    service: str
    counters: dict[str, int]

    def _body(self) -> dict[str, Any]:
        return {"header": self.header.to_wire(), "service": self.service, "counters": self.counters}

    @classmethod
    def _from_body(cls, b: Body) -> ServiceCounters:
        return cls(
            header=Header.from_wire(b.get_map("header")),
            service=b.get_str("service"),
            counters=b.int_map("counters"),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class MetricsSnapshot(_Message):
    """The metrics service's view of the stack over its sliding window.

    ``latency_ms`` maps a stage name (e.g. "capture_to_detections", "end_to_end") to its
    percentiles ({"p50", "p95", "p99", "mean", "count"}). ``counters`` maps
    "<service>.<counter>" to a count, bad input included.
    """

    TAG: ClassVar[str] = "MetricsSnapshot"
    header: Header
    window_s: float
    fps: float
    frames: int
    detections: int
    detections_per_frame: float
    dropped_frames: int
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

    def _body(self) -> dict[str, Any]:
        return {"header": self.header.to_wire(), **self.to_json_dict()}

    @classmethod
    def _from_body(cls, b: Body) -> MetricsSnapshot:
        lat = b.get_map("latency_ms")
        return cls(
            header=Header.from_wire(b.get_map("header")),
            window_s=b.get_float("window_s"),
            fps=b.get_float("fps"),
            frames=b.get_int("frames", 0),
            detections=b.get_int("detections", 0),
            detections_per_frame=b.get_float("detections_per_frame"),
            dropped_frames=b.get_int("dropped_frames", 0),
            latency_ms={k: lat.float_map(k) for k in lat.fields()},
            counters=b.int_map("counters"),
            class_counts=b.int_map("class_counts"),
        )
