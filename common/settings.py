"""Typed, frozen settings for every service: one table of the stack's TOML file each.

Each dataclass validates itself and raises ConfigError with one line for an out-of-range value.
Reading the file and the environment overrides is in common/config_file.py.

This module holds the bus, stack, metrics and supervisor settings and the whole ``Config``; the
perception settings (camera, detector, tracker) live in common/perception_settings.py and the
control settings (controller, sim) in common/control_settings.py, the ROS 2 bridge's in
common/ros2_settings.py, the live view's in common/viewer_settings.py, the recorder's in
common/recorder_settings.py. All are re-exported here, so
``from common.settings import X`` works for every one of them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from common.control_settings import ControllerSettings, SimSettings
from common.errors import ConfigError
from common.perception_settings import CameraSettings, DetectorSettings, TrackerSettings
from common.recorder_settings import RecorderSettings
from common.ros2_settings import Ros2Settings, check_camera_topics
from common.security import AUTH_MODES
from common.setting_checks import Bounds, check_bounds, check_lengths
from common.viewer_settings import ViewerSettings

__all__ = [
    "DEFAULT_CONFIG",
    "REPO_ROOT",
    "SERVICES",
    "CameraSettings",
    "Config",
    "ControllerSettings",
    "DetectorSettings",
    "MetricsSettings",
    "RecorderSettings",
    "Ros2Settings",
    "SimSettings",
    "StackSettings",
    "SupervisorSettings",
    "TrackerSettings",
    "ViewerSettings",
    "ZenohSettings",
]

REPO_ROOT = Path(__file__).resolve().parent.parent
# Runnable by the supervisor, and started in this order: the recorder first, so that it hears
# the others from their start; the viewer after what it watches.
#: The most cameras one stack serves (one detector process serves them all).
MAX_CAMERAS = 16
_CAMERA_NAME = re.compile(r"[a-z0-9][a-z0-9_]{0,31}")


def check_camera_name(name: str) -> None:
    """A camera name is a key chunk, a process name and a file name: ``[a-z0-9_]``, 1..32."""
    if not _CAMERA_NAME.fullmatch(name):
        raise ConfigError(
            f"camera name {name!r} must be 1..32 of a-z, 0-9 and _ (starting with a letter or "
            "digit): it names keys, processes and files"
        )


def camera_service(first: str, camera: str) -> str:
    """The service (process, health token, counters, principal) of ``camera``: ``camera`` for
    the first camera (``stack.camera``), as a one-camera stack has always named it, and
    ``camera_<name>`` for each further one."""
    return "camera" if camera == first else f"camera_{camera}"


def detector_service(n: int, worker_id: str = "") -> str:
    """The one name of this host's ``n``-th detector worker (from 1): its service, process,
    health token, counters key, pool id and principal. ``detector``, ``detector_2`` ... with
    no ``detector.worker_id`` (the first as a one-detector stack has always named it);
    ``detector_<id>``, ``detector_<id>_2`` ... with one, so that workers on several hosts,
    each host with its own id, never share a name."""
    base = f"detector_{worker_id}" if worker_id else "detector"
    return base if n == 1 else f"{base}_{n}"


#: Any detector worker's name, on any host (``detector_service``'s names): what the metrics
#: service believes counters from without knowing the other hosts' configs.
_DETECTOR_SERVICE = re.compile(r"detector(_[a-z0-9_]{1,40})?")


def is_detector_service(name: str) -> bool:
    """Whether ``name`` can be a detector worker's name (``detector``, ``detector_<chunk>``)."""
    return _DETECTOR_SERVICE.fullmatch(name) is not None


def service_package(service: str) -> str:
    """The package a service runs from, ``services.<package>``: ``camera`` for every camera's
    service (``camera``, ``camera_<name>``), ``detector`` for every detector worker's
    (``detector``, ``detector_<n>``), the service's own name otherwise."""
    for package in ("camera", "detector"):
        if service.startswith(f"{package}_"):
            return package
    return service


SERVICES = ("recorder", "camera", "sim", "ros2", "detector", "controller", "metrics", "viewer")
DEFAULT_CONFIG = REPO_ROOT / "deploy" / "stack.toml"
# zenoh.max_payload_bytes: a counters message must fit; Zenoh refuses to receive above 1 GiB.
MIN_PAYLOAD_LIMIT = 64 * 1024
MAX_PAYLOAD_LIMIT = 1 << 30


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

    ``max_payload_bytes`` is the largest payload a service sends; a larger one is counted
    (``payload_too_large``) and not sent, because Zenoh silently loses big payloads under
    congestion control DROP (64 MiB on loopback; 48 MiB still arrived). 32 MiB leaves a
    margin for a loaded host and fits a raw 3840x2160 bgr8 frame (24 MiB).
    """

    mode: str = "peer"
    # Not Zenoh's usual 7447: on a ROS 2 robot rmw_zenohd holds that one.
    endpoint: str = "tcp/127.0.0.1:7448"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ("tcp/127.0.0.1:0",)
    multicast_scouting: bool = False
    auth: str = "none"
    credentials_dir: str = "secrets"
    max_payload_bytes: int = 32 * 1024 * 1024

    BOUNDS: ClassVar[Bounds] = {"max_payload_bytes": (MIN_PAYLOAD_LIMIT, MAX_PAYLOAD_LIMIT)}
    LENGTHS: ClassVar[Bounds] = {"connect": (0, 16), "listen": (0, 16)}

    def __post_init__(self) -> None:
        check_bounds(self, "zenoh", self.BOUNDS)
        check_lengths(self, "zenoh", self.LENGTHS)
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

    BOUNDS: ClassVar[Bounds] = {"clock_tolerance_s": (0, 5)}

    def __post_init__(self) -> None:
        check_bounds(self, "stack", self.BOUNDS)


@dataclass(frozen=True, slots=True, kw_only=True)
class MetricsSettings:
    """The sliding window the percentiles cover, how often the report is logged, how much
    per-second history (FPS over time) is kept, and the optional Prometheus endpoint.

    ``prometheus_port`` 0 turns the endpoint off; it listens on ``prometheus_host`` (loopback by
    default, so that nothing is exposed to the network unless asked for).

    What is believed (services/metrics/trust.py): counters only from a known service on its own
    key, at most ``max_counters_per_service`` names each; a detector's stage times only within
    0..``max_timing_ms``. The rest is refused and counted as ``metrics.refused.<why>``. At most
    ``max_classes`` distinct class names are counted; a name beyond them is counted as
    ``metrics.class_names_refused`` (names longer than 128 characters never decode).
    Counters of a detector worker the config does not name (another host's pool worker,
    ``detector_<worker_id>``) are believed for the first ``max_workers`` such names heard; a
    further one is refused (``metrics.refused.too_many_workers``).
    """

    window_s: float = 10.0
    report_period_s: float = 5.0
    history_s: float = 600.0
    prometheus_port: int = 0
    prometheus_host: str = "127.0.0.1"
    max_counters_per_service: int = 256
    max_timing_ms: float = 1e6
    max_classes: int = 1000
    max_workers: int = 32

    BOUNDS: ClassVar[Bounds] = {
        "window_s": (0.1, 3600),
        "report_period_s": (0.1, 3600),
        "history_s": (1, 86400),
        "prometheus_port": (0, 65535),  # 0 = off
        "max_counters_per_service": (1, 2000),
        "max_timing_ms": (0.001, 1e9),
        "max_classes": (1, 10000),
        "max_workers": (0, 1000),
    }

    def __post_init__(self) -> None:
        check_bounds(self, "metrics", self.BOUNDS)
        if not self.prometheus_host:
            raise ConfigError("metrics.prometheus_host must not be empty")


@dataclass(frozen=True, slots=True, kw_only=True)
class SupervisorSettings:
    """Which services to run and how to restart them (exponential backoff, capped).

    One supervisor per stack (endpoint and prefix) on a host: its lock file lives in
    ``lock_dir`` (empty: the system's temporary folder).

    The watchdog (deploy/watchdog.py) restarts a running service whose liveliness token has been
    gone for ``watchdog_grace_s``, or whose work loop has published no counters for
    ``watchdog_progress_s`` (0 turns that check off).

    A service that fails for good (bad config, model or backend: exit codes 2..4) stops the
    stack, unless it is ``optional``: then it is left stopped, said so once, and the rest runs
    on (the live view whose port is taken must not stop a robot's perception), and the run's
    exit code ignores it. The viewer and the recorder are optional by default: they only
    watch the bus, and no other service reads anything from them.
    """

    services: tuple[str, ...] = ("camera", "detector", "controller", "metrics")
    optional: tuple[str, ...] = ("viewer", "recorder")
    restart_backoff_s: float = 0.5
    restart_backoff_max_s: float = 10.0
    stop_timeout_s: float = 5.0
    status_period_s: float = 2.0
    lock_dir: str = ""
    watchdog_grace_s: float = 2.0
    watchdog_progress_s: float = 20.0

    BOUNDS: ClassVar[Bounds] = {
        "restart_backoff_s": (0.01, 60),
        "restart_backoff_max_s": (0.01, 600),
        "stop_timeout_s": (0.1, 60),
        "status_period_s": (0.1, 60),
        "watchdog_grace_s": (0.1, 60),
        "watchdog_progress_s": (0, 600),  # 0 = off
    }
    LENGTHS: ClassVar[Bounds] = {"optional": (0, len(SERVICES))}

    def __post_init__(self) -> None:
        unknown = sorted(set(self.services) - set(SERVICES))
        if unknown or len(set(self.services)) != len(self.services) or not self.services:
            raise ConfigError(
                f"supervisor.services must name each of {', '.join(SERVICES)} at most once, "
                f"got {list(self.services)}"
            )
        check_bounds(self, "supervisor", self.BOUNDS)
        check_lengths(self, "supervisor", self.LENGTHS)
        if set(self.optional) - set(SERVICES):
            raise ConfigError(
                f"supervisor.optional must name services among {', '.join(SERVICES)}, "
                f"got {list(self.optional)}"
            )
        if self.restart_backoff_max_s < self.restart_backoff_s:
            raise ConfigError(
                f"supervisor.restart_backoff_max_s ({self.restart_backoff_max_s}) must not be "
                f"below supervisor.restart_backoff_s ({self.restart_backoff_s})"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class Config:
    """The whole stack configuration; each service reads its own table."""

    path: str = ""
    zenoh: ZenohSettings = field(default_factory=ZenohSettings)
    stack: StackSettings = field(default_factory=StackSettings)
    camera: CameraSettings = field(default_factory=CameraSettings)
    #: Further cameras, ``[cameras.<name>]`` tables: each is [camera] with its own changes
    #: (common/config_file.py builds them). The first camera is ``stack.camera`` = [camera].
    cameras: tuple[tuple[str, CameraSettings], ...] = ()
    detector: DetectorSettings = field(default_factory=DetectorSettings)
    tracker: TrackerSettings = field(default_factory=TrackerSettings)
    controller: ControllerSettings = field(default_factory=ControllerSettings)
    sim: SimSettings = field(default_factory=SimSettings)
    metrics: MetricsSettings = field(default_factory=MetricsSettings)
    ros2: Ros2Settings = field(default_factory=Ros2Settings)
    viewer: ViewerSettings = field(default_factory=ViewerSettings)
    recorder: RecorderSettings = field(default_factory=RecorderSettings)
    supervisor: SupervisorSettings = field(default_factory=SupervisorSettings)

    def __post_init__(self) -> None:
        names = [self.stack.camera, *(name for name, _ in self.cameras)]
        if len(names) > MAX_CAMERAS:
            raise ConfigError(f"at most {MAX_CAMERAS} cameras, got {len(names)}: {names}")
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ConfigError(
                f"camera names must differ: {twice} named twice (stack.camera is the first "
                "camera, [cameras.<name>] the others)"
            )
        for name in names:
            check_camera_name(name)
        if len(names) > 1:
            check_camera_topics(self.ros2, names)  # each camera's own ROS 2 topics
        unknown = sorted(set(self.sim.wait_for) - set(SERVICES))
        if unknown:
            raise ConfigError(
                f"sim.wait_for must name services among {', '.join(SERVICES)}, got {unknown}"
            )

    @property
    def all_cameras(self) -> dict[str, CameraSettings]:
        """Every camera by name, the first (``stack.camera``, the [camera] table) first."""
        return {self.stack.camera: self.camera, **dict(self.cameras)}

    @property
    def camera_services(self) -> dict[str, str]:
        """Every camera's service name (see :func:`camera_service`) by camera name."""
        return {c: camera_service(self.stack.camera, c) for c in self.all_cameras}

    @property
    def detector_services(self) -> tuple[str, ...]:
        """The names of every detector worker this host runs (``detector.workers`` of them;
        see :func:`detector_service`): each is its service, pool id and principal."""
        d = self.detector
        return tuple(detector_service(n, d.worker_id) for n in range(1, d.workers + 1))

    def camera_settings(self, name: str) -> CameraSettings:
        """The settings of camera ``name``; ConfigError naming the known ones otherwise."""
        cameras = self.all_cameras
        if name not in cameras:
            raise ConfigError(f"no camera {name!r} in the config; known: {list(cameras)}")
        return cameras[name]

    @property
    def estop_path(self) -> Path:
        """Where the controller keeps the latched e-stop (one file per stack prefix)."""
        default = f"state/estop-{self.stack.prefix.replace('/', '_')}.json"
        name = self.controller.estop_file or default
        path = Path(name).expanduser()
        return path if path.is_absolute() else REPO_ROOT / path
