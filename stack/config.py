"""The whole stack configuration, assembled from every service's settings (each declared in its
contract, ``services/<name>/contract.py``) and the shared ones (common/settings.py); read from
the TOML file and the environment in stack/config_file.py."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

from common.errors import ConfigError
from common.setting_checks import Length, Range, check_bounds, check_lengths
from common.settings import (
    MAX_CAMERAS,
    REPO_ROOT,
    SERVICES,
    StackSettings,
    ZenohSettings,
    camera_service,
    check_camera_name,
    detector_service,
    principal_name,
)
from services.camera.contract import CameraSettings
from services.controller.contract import ControllerSettings
from services.detector.contract import DetectorSettings, TrackerSettings
from services.metrics.contract import MetricsSettings
from services.recorder.contract import RecorderSettings
from services.ros2.contract import Ros2Settings, check_camera_topics
from services.sim.contract import SimSettings
from services.viewer.contract import ViewerSettings
from stack.config_read import estop_file_path
from stack.contracts import check_config_tables

__all__ = ["Config", "SupervisorSettings"]


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

    services: tuple[str, ...] = ("sim", "detector", "controller", "metrics", "viewer")
    optional: Annotated[tuple[str, ...], Length(0, len(SERVICES))] = ("viewer", "recorder")
    restart_backoff_s: Annotated[float, Range(0.01, 60)] = 0.5
    restart_backoff_max_s: Annotated[float, Range(0.01, 600)] = 10.0
    stop_timeout_s: Annotated[float, Range(0.1, 60)] = 5.0
    status_period_s: Annotated[float, Range(0.1, 60)] = 2.0
    lock_dir: str = ""
    watchdog_grace_s: Annotated[float, Range(0.1, 60)] = 2.0
    watchdog_progress_s: Annotated[float, Range(0, 600)] = 20.0  # 0 = off

    def __post_init__(self) -> None:
        unknown = sorted(set(self.services) - set(SERVICES))
        if unknown or len(set(self.services)) != len(self.services) or not self.services:
            raise ConfigError(
                f"supervisor.services must name each of {', '.join(SERVICES)} at most once, "
                f"got {list(self.services)}"
            )
        check_bounds(self, "supervisor", SupervisorSettings)
        check_lengths(self, "supervisor", SupervisorSettings)
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
    #: (stack/config_file.py builds them). The first camera is ``stack.camera`` = [camera].
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
        run = self.supervisor.services
        if self.controller.needs_depth and "controller" in run and "depthscan" not in run:
            raise ConfigError(
                "the controller needs depth (controller.obstacle_sources or distance_source) "
                'and reads it from the depth scan stage: add "depthscan" to supervisor.services'
            )
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

    def principal(self, role: str) -> str:
        """The name ``role`` (a service's, ``estop``, ``observer``) authenticates as on this
        stack: ``<stack.prefix>/<role>``, a detector worker's ``<pool>/<worker>``
        (common.settings.principal_name, docs/security.md)."""
        return principal_name(self.stack.prefix, role, self.detector.pool_prefix)

    def camera_settings(self, name: str) -> CameraSettings:
        """The settings of camera ``name``; ConfigError naming the known ones otherwise."""
        cameras = self.all_cameras
        if name not in cameras:
            raise ConfigError(f"no camera {name!r} in the config; known: {list(cameras)}")
        return cameras[name]

    @property
    def depth_memory_path(self) -> Path:
        """Where the depth scan stage keeps its depth map across restarts (one file per
        prefix; ``controller.depth_memory_file``)."""
        default = f"state/depth-memory-{self.stack.prefix.replace('/', '_')}.npz"
        path = Path(self.controller.depth_memory_file or default).expanduser()
        return path if path.is_absolute() else REPO_ROOT / path

    @property
    def estop_path(self) -> Path:
        """Where the controller keeps the latched e-stop (one file per stack prefix)."""
        return estop_file_path(self.stack.prefix, self.controller.estop_file)


# Each service's tables, as its contract declares them (SETTINGS_TABLES), and no other: typed
# fields above, so that every reader is type-checked; a listed service's table missing here
# stops the stack at import with the line to add.
check_config_tables(Config)
