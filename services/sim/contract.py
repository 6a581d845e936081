"""The simulator's contract: its counters and what it puts and reads. Imports only ``common``.

The simulator renders every camera from one world and plays the laser and the robot's base: it
puts every camera's frames and depth images (and announces every camera), the scan and the
ground truth, and reads the velocity commands.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Annotated

from common.access import Access, Shape, service_access
from common.counters import COMMON
from common.errors import ConfigError
from common.setting_checks import Length, Range, check_bounds, check_lengths, enum_field

FRAMES_OUT = "frames_out"  # in all and per camera
DEPTH_OUT = "depth_out"  # depth images (sim.depth), in all and per camera
COMMANDS_OUT_OF_RANGE = "commands_out_of_range"  # beyond what the base takes: it stops
COMMANDS_FROM_SEVERAL_SOURCES = "commands_from_several_sources"
#: Milliseconds the world fell behind the wall clock beyond ``sim.catch_up_max_s`` a pass and
#: did not make up (services/sim/pacing.py): a CPU so starved that the world ran slow.
PHYSICS_BEHIND_MS = "physics_behind_ms"

PER_CAMERA = frozenset({FRAMES_OUT, DEPTH_OUT})
COUNTERS = frozenset(
    {
        *COMMON,
        FRAMES_OUT,
        DEPTH_OUT,
        COMMANDS_OUT_OF_RANGE,
        COMMANDS_FROM_SEVERAL_SOURCES,
        PHYSICS_BEHIND_MS,
    }
)

SERVICE = "sim"
#: It feeds a (simulated) robot's sensors into the stack: no recording may be played onto it.
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
            *map(keys.depth, shape.cameras),
            keys.scan(),
            keys.sim_truth(),
            # cmd_vel drives the base; each camera's detections start the scenario's clock
            # (sim.wait_for's "detector", services/sim/waiting.py).
            read=(keys.cmd_vel(), *map(keys.detections, shape.cameras)),
            token=(keys.health(SERVICE), *map(keys.camera_announcements_of, shape.cameras)),
        )
    }


# -- settings -------------------------------------------------------------------------------------
class SimWorld(StrEnum):
    """How hard the simulated world is (``sim.world``)."""

    HARD = "hard"  # the newer camera faults on, with their settings (the default)
    SIMPLE = "simple"  # today's world and camera: the newer fault settings are ignored


#: What ``sim.world = "simple"`` sets each newer fault setting to, whatever the config says:
#: off, today's camera. The setting's own default is the harder world's.
SIMPLE_FAULTS: dict[str, float] = {
    "depth_bias_k": 0.0,
    "depth_flying_share": 0.0,
    "depth_mirror_scale": 1.0,
    "depth_noise_in_disparity": False,
    "colour_exposure_ms": 0.0,
    "colour_light_change": 0.0,
    "colour_drift": 0.0,
}


@dataclass(frozen=True, slots=True, kw_only=True)
class SimSettings:
    """The simulated robot and world (services/sim), standing in for a camera and a base.

    ``scenario`` names a world in simworld/scenarios.py. The scenario clock starts once
    what ``wait_for`` names has come, so start-up time does not eat into the scenario:
    ``detector`` as the detections of every camera it renders (from any worker, a pool's on
    another host too), any other service by its health token (services/sim/waiting.py).
    The camera uses camera.hfov_deg; the image is ``width`` x ``height``. With ``ros2_robot``
    the simulator plays a ROS 2 robot: it hosts the graph's router on ``ros2.router`` and
    speaks ROS 2 messages on the topics of ``[ros2]``, so that the ``ros2`` bridge service
    carries every frame, scan and command. Commands from more
    than one publisher within ``command_sources_window_s`` are counted and warned about.

    ``catch_up_max_s``: the world keeps the wall clock's time (services/sim/pacing.py): a
    pass slower than a physics step takes the steps it owes, up to this much time a pass (the
    rest counted ``physics_behind_ms``), so that a starved simulator does not slow the base.

    ``laser``: false plays a robot with no laser (no scan at all). ``laser_height_m``: the
    height of its scan plane above the floor (0.2 m: a 2D lidar on a small base); it sees only
    obstacles taller than that, never a glass one and never a drop-off (simworld/world.py).
    ``depth``: every camera is an RGB-D camera: one DepthFrame per colour frame, with the
    colour frame's header, on ``keys.depth(camera)`` (simworld/depth.py), with a stereo
    camera's faults: the ``depth_*`` settings are the fields of ``DepthNoise`` there
    (``depth_range_min_m`` below ``depth_range_max_m``); as a ROS 2 robot, a 16UC1
    ``sensor_msgs/Image`` and its ``CameraInfo`` on ``ros2.depth_topic`` and
    ``ros2.depth_info_topic`` instead.

    ``world``: ``"hard"`` (the default) runs the newer faults, each its own setting with its
    source in simworld/depth.py's ``DepthNoise`` and simworld/faults.py: the depth camera's
    range bias (``depth_bias_k``), flying pixels at depth edges (``depth_flying_share``),
    mirrors that read too far (``depth_mirror_scale``), noise and bias in disparity, not
    range (``depth_noise_in_disparity``), and the colour camera's motion blur
    (``colour_exposure_ms``) and exposure changes (``colour_light_*``, ``colour_drift*``).
    ``"simple"`` is today's world: it sets those fault settings off (:data:`SIMPLE_FAULTS`)
    whatever the config says, keeps the older ``depth_*`` settings, and draws people flat.
    The simulator's log says at start which world and which faults run (one line,
    services/sim/worlds.py ``world_line``).
    """

    scenario: str = "demo"
    wait_for: Annotated[tuple[str, ...], Length(0, 6)] = ("detector", "controller")
    physics_hz: Annotated[float, Range(1, 1000)] = 50.0
    catch_up_max_s: Annotated[float, Range(0, 5)] = 0.2
    camera_rate_hz: Annotated[float, Range(0.1, 100)] = 5.0
    scan_rate_hz: Annotated[float, Range(0.1, 100)] = 10.0
    truth_rate_hz: Annotated[float, Range(0.1, 100)] = 20.0
    width: Annotated[int, Range(16, 4096)] = 640
    height: Annotated[int, Range(16, 4096)] = 480
    camera_height_m: Annotated[float, Range(0.05, 5)] = 0.6
    laser_fov_deg: Annotated[float, Range(1, 360)] = 270.0
    laser_rays: Annotated[int, Range(2, 10000)] = 541  # real 2D lidars: 360..3200 rays a scan
    laser_range_max_m: Annotated[float, Range(0.1, 100)] = 12.0
    laser_noise_m: Annotated[float, Range(0, 1)] = 0.01
    laser_height_m: Annotated[float, Range(0.01, 2)] = 0.2  # on the base's deck .. on a mast
    seed: Annotated[int, Range(0, 2**32 - 1)] = 0
    ros2_robot: bool = False
    command_sources_window_s: Annotated[float, Range(0.01, 60)] = 1.0
    laser: bool = True
    depth: bool = False
    depth_range_min_m: Annotated[float, Range(0, 10)] = 0.3
    depth_range_max_m: Annotated[float, Range(0.1, 65)] = 10.0  # a 16UC1 image holds up to 65.535 m
    depth_noise_k: Annotated[float, Range(0, 1)] = 0.005
    depth_noise_corr_px: Annotated[float, Range(0, 50)] = 4.0
    depth_edge_px: Annotated[int, Range(0, 50)] = 2
    depth_edge_jump: Annotated[float, Range(0.001, 10)] = 0.1
    depth_dark_level: Annotated[int, Range(0, 255)] = 30
    depth_dark_dropout: Annotated[float, Range(0, 1)] = 0.5
    depth_dropout: Annotated[float, Range(0, 1)] = 0.01
    world: SimWorld = SimWorld.HARD
    depth_bias_k: Annotated[float, Range(-0.05, 0.05)] = 0.0025  # 0.5 % at 2 m (D435: <= 2 %)
    depth_flying_share: Annotated[float, Range(0, 1)] = 0.5
    depth_mirror_scale: Annotated[float, Range(1, 10)] = 2.0
    depth_noise_in_disparity: bool = True
    colour_exposure_ms: Annotated[float, Range(0, 100)] = 20.0
    colour_light_change: Annotated[float, Range(0, 2)] = 0.3
    colour_light_tau_s: Annotated[float, Range(0.01, 60)] = 1.0
    colour_drift: Annotated[float, Range(0, 1)] = 0.05
    colour_drift_tau_s: Annotated[float, Range(0.1, 600)] = 10.0

    def __post_init__(self) -> None:
        check_bounds(self, "sim", SimSettings)
        check_lengths(self, "sim", SimSettings)
        enum_field(self, "world", SimWorld, "sim.world")
        if self.depth_range_min_m >= self.depth_range_max_m:
            raise ConfigError(
                f"sim.depth_range_min_m ({self.depth_range_min_m:g}) must be below "
                f"sim.depth_range_max_m ({self.depth_range_max_m:g})"
            )


#: The stack config's tables this service reads (stack/config.py's Config has each).
SETTINGS_TABLES = {"sim": SimSettings}
