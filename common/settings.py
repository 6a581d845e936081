"""Typed, frozen settings for every service: one table of the stack's TOML file each.

Each dataclass validates itself and raises ConfigError with one line for an out-of-range value.
Reading the file and the environment overrides is in common/config_file.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

from common.contracts import BackendName, ControllerMode, DistanceSource
from common.errors import ConfigError
from common.messages import MAX_DETECTIONS, MAX_IMAGE_SIDE
from common.security import AUTH_MODES

REPO_ROOT = Path(__file__).resolve().parent.parent
SERVICES = ("camera", "sim", "detector", "controller", "metrics")  # runnable by the supervisor
DEFAULT_CONFIG = REPO_ROOT / "deploy" / "stack.toml"


def _positive(name: str, value: float) -> None:
    if not (value > 0 and math.isfinite(value)):
        raise ConfigError(f"{name} must be a positive number, got {value}")


def _non_negative(name: str, value: float) -> None:
    if not (value >= 0 and math.isfinite(value)):
        raise ConfigError(f"{name} must be a finite number >= 0, got {value}")


def _enum(settings: object, name: str, kind: type[StrEnum], where: str) -> None:
    """Turn a plain string field into its enum member (settings built in code pass strings)."""
    value = getattr(settings, name)
    try:
        object.__setattr__(settings, name, kind(value))
    except ValueError:
        choices = ", ".join(m.value for m in kind)
        raise ConfigError(f"{where} must be one of {choices}, got {value!r}") from None


def _fraction(name: str, value: float) -> None:
    if not 0 <= value <= 1:
        raise ConfigError(f"{name} must be within 0..1, got {value}")


@dataclass(frozen=True, slots=True, kw_only=True)
class ZenohSettings:
    """How every process joins the bus.

    The supervisor listens on ``endpoint``; services connect to it and to ``connect`` (other
    hosts), and listen on ``listen`` (port 0: any free port) so that peers mesh directly.
    Multicast scouting is off by default: robots share networks, and tests must stay private.

    ``mode = "client"`` makes the supervisor a Zenoh router that every service joins, so that
    all traffic passes through it. ``auth`` ("none", "password" or "certificate") turns on
    authentication and access control there, with the credentials that
    ``zstack credentials`` writes to ``credentials_dir`` (relative to the repo root);
    it needs client mode. An endpoint ``tls/<host>:<port>`` encrypts the links with the same
    credentials; "certificate" needs one (mutual TLS). See docs/security.md.
    """

    mode: str = "peer"
    endpoint: str = "tcp/127.0.0.1:7447"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ("tcp/127.0.0.1:0",)
    multicast_scouting: bool = False
    auth: str = "none"
    credentials_dir: str = "secrets"

    def __post_init__(self) -> None:
        if self.mode not in ("peer", "client"):
            raise ConfigError(f"zenoh.mode must be 'peer' or 'client', got {self.mode!r}")
        for ep in (self.endpoint, *self.connect, *self.listen):
            if "/" not in ep:
                raise ConfigError(f"zenoh endpoint {ep!r} must look like tcp/<host>:<port>")
        if self.auth not in AUTH_MODES:
            modes = ", ".join(AUTH_MODES)
            raise ConfigError(f"zenoh.auth must be one of {modes}, got {self.auth!r}")
        if self.auth != "none" and self.mode != "client":
            raise ConfigError(
                'zenoh.auth needs zenoh.mode = "client": access control runs on the supervisor\'s '
                "router, which must see every message"
            )
        if self.auth == "certificate" and not self.uses_tls:
            raise ConfigError('zenoh.auth = "certificate" needs a tls/<host>:<port> endpoint')
        if not self.credentials_dir:
            raise ConfigError("zenoh.credentials_dir must not be empty")

    @property
    def uses_tls(self) -> bool:
        return any(ep.startswith("tls/") for ep in (self.endpoint, *self.connect))

    @property
    def credentials_path(self) -> Path:
        path = Path(self.credentials_dir).expanduser()
        return path if path.is_absolute() else REPO_ROOT / path


@dataclass(frozen=True, slots=True, kw_only=True)
class StackSettings:
    """Names shared by all services (the key prefix and the camera they work on), and how far
    ahead of the receiver's clock a stamp may be before it counts as from the future
    (``clock_tolerance_s``: the clock offset allowed between hosts; see docs/security.md)."""

    prefix: str = "stack"
    camera: str = "front"
    clock_tolerance_s: float = 0.1

    def __post_init__(self) -> None:
        if not 0 <= self.clock_tolerance_s <= 5:
            raise ConfigError(
                f"stack.clock_tolerance_s must be within 0..5 s, got {self.clock_tolerance_s}"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraSettings:
    """The frame source.

    ``source`` is one of: ``sample:<name>`` (a scikit-image photo: astronaut, cameraman, chelsea,
    coffee, rocket, motorcycle), a path to an image (repeated), a folder of images (looped), a
    video file (looped when ``loop``), or ``device:<index or /dev/videoN>`` (webcam / V4L2).
    ``resize`` is (width, height), or (0, 0) to keep the source size. ``jpeg_quality`` 0 sends
    raw bgr8; 1..100 sends JPEG at that quality. ``hfov_deg`` is the horizontal field of view,
    which turns a pixel column into a bearing (the controller and the simulator use it).
    """

    source: str = "sample:cameraman"
    rate_hz: float = 10.0
    resize: tuple[int, int] = (0, 0)
    jpeg_quality: int = 0
    frame_id: str = "camera"
    loop: bool = True
    hfov_deg: float = 60.0

    def __post_init__(self) -> None:
        _positive("camera.rate_hz", self.rate_hz)
        if (
            min(self.resize) < 0
            or max(self.resize) > MAX_IMAGE_SIDE
            or (0 in self.resize and self.resize != (0, 0))
        ):
            raise ConfigError(
                f"camera.resize must be [w, h] within 1..{MAX_IMAGE_SIDE} or [0, 0], "
                f"got {list(self.resize)}"
            )
        if not 0 <= self.jpeg_quality <= 100:
            raise ConfigError(f"camera.jpeg_quality must be 0..100, got {self.jpeg_quality}")
        if not 1 <= self.hfov_deg <= 179:
            raise ConfigError(f"camera.hfov_deg must be within 1..179, got {self.hfov_deg}")


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectorSettings:
    """The model, its backend and the post-processing thresholds.

    ``model`` empty means the default COCO model (fetched at setup). ``backend`` is onnx,
    tensorrt, cuda or auto (auto picks tensorrt, then cuda, then onnx: docs/tensorrt.md).
    ``precision`` empty leaves the backend's default (fp32 on the CPU, fp16 on a GPU); GPU
    backends take fp32 or fp16, TensorRT also int8. ``batch_profile`` is the (min, opt, max)
    batch a TensorRT engine is built for; the service sends single frames, so (1, 1, 1).
    ``classes`` empty keeps every class. A frame captured more than ``max_frame_age_s`` ago,
    stamped in the future or replayed is not detected on (counted, see common/freshness.py).
    """

    model: str = ""
    backend: BackendName = BackendName.ONNX
    precision: str = ""
    batch_profile: tuple[int, int, int] = (1, 1, 1)
    conf: float = 0.25
    iou: float = 0.45
    max_det: int = 100
    classes: tuple[str, ...] = ()
    max_frame_age_s: float = 1.0
    counters_period_s: float = 1.0

    def __post_init__(self) -> None:
        _positive("detector.max_frame_age_s", self.max_frame_age_s)
        _enum(self, "backend", BackendName, "detector.backend")
        if self.precision not in ("", "fp32", "fp16", "int8"):
            raise ConfigError(
                f"detector.precision must be one of fp32, fp16, int8 (or empty for the "
                f"backend's default), got {self.precision!r}"
            )
        lo, opt, hi = self.batch_profile
        if not 1 <= lo <= opt <= hi:
            raise ConfigError(
                f"detector.batch_profile must be [min, opt, max] with 1 <= min <= opt <= max, "
                f"got {list(self.batch_profile)}"
            )
        _fraction("detector.conf", self.conf)
        _fraction("detector.iou", self.iou)
        if not 1 <= self.max_det <= MAX_DETECTIONS:
            raise ConfigError(
                f"detector.max_det must be within 1..{MAX_DETECTIONS}, got {self.max_det}"
            )
        _positive("detector.counters_period_s", self.counters_period_s)


@dataclass(frozen=True, slots=True, kw_only=True)
class TrackerSettings:
    """The detector's multi-object tracker, which gives Detections their track ids.

    ``high_score`` starts a track, ``low_score`` may only extend one, ``iou`` is the least
    overlap with a track's predicted box, and a track unseen for ``max_age_s`` is dropped.
    A frame whose stamp moved by more than ``max_stamp_jump_s`` beyond the time that really
    passed between arrivals (or went back) is ignored, not allowed to age every track out.
    """

    enabled: bool = True
    high_score: float = 0.4
    low_score: float = 0.15
    iou: float = 0.25
    max_age_s: float = 1.0
    max_stamp_jump_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("high_score", "low_score", "iou"):
            _fraction(f"tracker.{name}", getattr(self, name))
        if self.low_score > self.high_score:
            raise ConfigError("tracker.low_score must not be above tracker.high_score")
        _positive("tracker.max_age_s", self.max_age_s)
        _positive("tracker.max_stamp_jump_s", self.max_stamp_jump_s)


@dataclass(frozen=True, slots=True, kw_only=True)
class ControllerSettings:
    """The reaction policy. Speeds in m/s and rad/s, angles in degrees, times in seconds.

    track:  turn towards the most central confident detection of ``target_classes``; drive
            forward at ``forward_speed`` only while it is within ``center_tolerance`` (a
            fraction of the image width) of the image centre.
    follow: lock onto the largest detection of ``target_classes[0]`` (by track id, so it does
            not jump to another person) and keep it at ``follow_distance_m``, measured from the
            box height (``distance_source = "box"``, for a target ``target_height_m`` tall) or
            by the laser in the target's bearing (``"laser"``). Forward only while centred and
            while the laser sector of ``sector_width_deg`` straight ahead, and the corridor
            ``robot_width_m`` wide that the body sweeps, are clear beyond ``safety_distance_m``
            plus the room needed to brake. A box cut by the image edge counts as arrived.
            A target unseen for ``target_lost_timeout_s`` is dropped.
    Both turn with a PID on the bearing error (rad -> rad/s) and obey the speed and
    acceleration limits. Stale detections (captured or received longer than
    ``detection_timeout_s`` ago) and the e-stop command zero at once, bypassing the
    acceleration limit. The latched e-stop is kept in ``estop_file`` (relative to the repo
    root; empty: ``state/estop-<prefix>.json``), so that it survives every restart; a release
    captured more than ``estop_release_max_age_s`` ago is refused.
    """

    mode: ControllerMode = ControllerMode.TRACK
    target_classes: tuple[str, ...] = ("person",)
    min_score: float = 0.3
    control_rate_hz: float = 20.0
    detection_timeout_s: float = 1.0
    scan_timeout_s: float = 0.5
    target_lost_timeout_s: float = 1.5
    bearing_kp: float = 1.5
    bearing_ki: float = 0.0
    bearing_kd: float = 0.05
    max_angular: float = 1.0
    max_linear: float = 0.5
    max_angular_accel: float = 3.0
    max_linear_accel: float = 1.0
    forward_speed: float = 0.3
    center_tolerance: float = 0.1
    distance_source: DistanceSource = DistanceSource.BOX
    follow_distance_m: float = 1.0
    distance_gain: float = 0.6
    target_height_m: float = 1.7
    safety_distance_m: float = 0.5
    sector_width_deg: float = 30.0
    robot_width_m: float = 0.6
    estop_file: str = ""
    estop_release_max_age_s: float = 2.0
    counters_period_s: float = 1.0

    def __post_init__(self) -> None:
        _enum(self, "mode", ControllerMode, "controller.mode")
        _enum(self, "distance_source", DistanceSource, "controller.distance_source")
        if not self.target_classes:
            raise ConfigError("controller.target_classes needs at least one class name")
        for name in (
            "control_rate_hz",
            "detection_timeout_s",
            "scan_timeout_s",
            "target_lost_timeout_s",
            "max_angular",
            "max_linear",
            "max_angular_accel",
            "max_linear_accel",
            "follow_distance_m",
            "target_height_m",
            "safety_distance_m",
            "sector_width_deg",
            "robot_width_m",
            "estop_release_max_age_s",
            "counters_period_s",
        ):
            _positive(f"controller.{name}", getattr(self, name))
        for name in ("bearing_kp", "bearing_ki", "bearing_kd", "distance_gain"):
            _non_negative(f"controller.{name}", getattr(self, name))
        for name in ("min_score", "center_tolerance"):
            _fraction(f"controller.{name}", getattr(self, name))
        if not 0 <= self.forward_speed <= self.max_linear:
            raise ConfigError("controller.forward_speed must be within 0..max_linear")


@dataclass(frozen=True, slots=True, kw_only=True)
class SimSettings:
    """The simulated robot and world (services/sim), standing in for a camera and a base.

    ``scenario`` names a world in services/sim/scenarios.py. The scenario clock starts once
    every service in ``wait_for`` is ready, so start-up time does not eat into the scenario.
    The camera uses camera.hfov_deg; the image is ``width`` x ``height``. Commands from more
    than one publisher within ``command_sources_window_s`` are counted and warned about.
    """

    scenario: str = "demo"
    wait_for: tuple[str, ...] = ("detector", "controller")
    physics_hz: float = 50.0
    camera_rate_hz: float = 5.0
    scan_rate_hz: float = 10.0
    truth_rate_hz: float = 20.0
    width: int = 640
    height: int = 480
    camera_height_m: float = 0.6
    laser_fov_deg: float = 270.0
    laser_rays: int = 541
    laser_range_max_m: float = 12.0
    laser_noise_m: float = 0.01
    seed: int = 0
    command_sources_window_s: float = 1.0

    def __post_init__(self) -> None:
        for name in (
            "physics_hz",
            "camera_rate_hz",
            "scan_rate_hz",
            "truth_rate_hz",
            "camera_height_m",
            "laser_fov_deg",
            "laser_range_max_m",
        ):
            _positive(f"sim.{name}", getattr(self, name))
        if not (16 <= self.width <= 4096 and 16 <= self.height <= 4096):
            raise ConfigError(f"sim image size {self.width}x{self.height} is out of range")
        if self.laser_rays < 2:
            raise ConfigError(f"sim.laser_rays must be >= 2, got {self.laser_rays}")
        _non_negative("sim.laser_noise_m", self.laser_noise_m)
        _positive("sim.command_sources_window_s", self.command_sources_window_s)
        if self.seed < 0:
            raise ConfigError(f"sim.seed must be >= 0, got {self.seed}")


@dataclass(frozen=True, slots=True, kw_only=True)
class MetricsSettings:
    """The sliding window the percentiles cover, how often the report is logged, how much
    per-second history (FPS over time) is kept, and the optional Prometheus endpoint.

    ``prometheus_port`` 0 turns the endpoint off; it listens on ``prometheus_host`` (loopback by
    default, so that nothing is exposed to the network unless asked for).
    """

    window_s: float = 10.0
    report_period_s: float = 5.0
    history_s: float = 600.0
    prometheus_port: int = 0
    prometheus_host: str = "127.0.0.1"

    def __post_init__(self) -> None:
        _positive("metrics.window_s", self.window_s)
        _positive("metrics.report_period_s", self.report_period_s)
        _positive("metrics.history_s", self.history_s)
        if not 0 <= self.prometheus_port <= 65535:
            raise ConfigError(
                f"metrics.prometheus_port must be 0..65535 (0 = off), got {self.prometheus_port}"
            )
        if not self.prometheus_host:
            raise ConfigError("metrics.prometheus_host must not be empty")


@dataclass(frozen=True, slots=True, kw_only=True)
class SupervisorSettings:
    """Which services to run and how to restart them (exponential backoff, capped).

    One supervisor per stack (endpoint and prefix) on a host: its lock file lives in
    ``lock_dir`` (empty: the system's temporary folder).
    """

    services: tuple[str, ...] = ("camera", "detector", "controller", "metrics")
    restart_backoff_s: float = 0.5
    restart_backoff_max_s: float = 10.0
    stop_timeout_s: float = 5.0
    status_period_s: float = 2.0
    lock_dir: str = ""

    def __post_init__(self) -> None:
        unknown = sorted(set(self.services) - set(SERVICES))
        if unknown or len(set(self.services)) != len(self.services) or not self.services:
            raise ConfigError(
                f"supervisor.services must name each of {', '.join(SERVICES)} at most once, "
                f"got {list(self.services)}"
            )
        for name in (
            "restart_backoff_s",
            "restart_backoff_max_s",
            "stop_timeout_s",
            "status_period_s",
        ):
            _positive(f"supervisor.{name}", getattr(self, name))


@dataclass(frozen=True, slots=True, kw_only=True)
class Config:
    """The whole stack configuration; each service reads its own table."""

    path: str = ""
    zenoh: ZenohSettings = field(default_factory=ZenohSettings)
    stack: StackSettings = field(default_factory=StackSettings)
    camera: CameraSettings = field(default_factory=CameraSettings)
    detector: DetectorSettings = field(default_factory=DetectorSettings)
    tracker: TrackerSettings = field(default_factory=TrackerSettings)
    controller: ControllerSettings = field(default_factory=ControllerSettings)
    sim: SimSettings = field(default_factory=SimSettings)
    metrics: MetricsSettings = field(default_factory=MetricsSettings)
    supervisor: SupervisorSettings = field(default_factory=SupervisorSettings)

    @property
    def estop_path(self) -> Path:
        """Where the controller keeps the latched e-stop (one file per stack prefix)."""
        default = f"state/estop-{self.stack.prefix.replace('/', '_')}.json"
        name = self.controller.estop_file or default
        path = Path(name).expanduser()
        return path if path.is_absolute() else REPO_ROOT / path
