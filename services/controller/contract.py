"""The controller's contract: its counters, and what it and the operator's e-stop tool
(``zstack estop``, services/controller/estop_command.py) put and read. Imports only ``common``.

Only the controller puts ``cmd_vel``; only the ``estop`` principal the e-stop.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from common.access import Access, Shape, service_access
from common.contracts import ControllerMode, DistanceSource
from common.counters import COMMON, input_counters
from common.errors import ConfigError
from common.setting_checks import Length, Range, check_bounds, check_lengths, enum_field

# Its inputs, each counted by its fate (common/counters.py ``input_counter``): ``detections_in``,
# ``detections_stale`` ...; the detections' for each announced camera too.
DETECTIONS = "detections"
SCANS = "scans"
#: The depth cameras' virtual scans (services/depthscan/: one per camera), what the depth memory
#: remembers round the robot and how far ahead it knows the floor; read when the controller
#: needs depth (ControllerSettings.needs_depth), each judged as the laser's scan is.
VIRTUAL_SCANS = "virtual_scans"
REMEMBERED = "remembered"
KNOWN_FLOOR = "known_floor"
#: Detections from a camera with no live announcement: ignored.
DETECTIONS_UNANNOUNCED = "detections_unannounced"
#: Virtual scans of a camera not announced, or announced without depth: ignored.
VIRTUAL_SCANS_UNANNOUNCED = "virtual_scans_unannounced"
ESTOP_RELEASE_REFUSED = "estop_release_refused"
ESTOP_ZERO_AT_ONCE = "estop_zero_at_once"
#: Datagrams on the local e-stop socket that were not an engage (common/estop_local.py): each
#: is taken as a press, as garbage on the e-stop key is.
ESTOP_LOCAL_BAD = "estop_local_bad"
COMMANDS_OUT = "commands_out"
COMMANDS_NONZERO = "commands_nonzero"
#: Follow mode's lock: the lost target's track taken back, or another track locked after one
#: was lost (a switch: perhaps to someone else).
LOCK_REGAINED = "lock_regained"
LOCK_SWITCHED = "lock_switched"

PER_CAMERA = frozenset(
    {
        *input_counters(DETECTIONS),
        *input_counters(VIRTUAL_SCANS),
    }
)
COUNTERS = frozenset(
    {
        *COMMON,
        *PER_CAMERA,
        *input_counters(SCANS),
        *input_counters(REMEMBERED),
        *input_counters(KNOWN_FLOOR),
        DETECTIONS_UNANNOUNCED,
        VIRTUAL_SCANS_UNANNOUNCED,
        ESTOP_RELEASE_REFUSED,
        ESTOP_ZERO_AT_ONCE,
        ESTOP_LOCAL_BAD,
        COMMANDS_OUT,
        COMMANDS_NONZERO,
        LOCK_REGAINED,
        LOCK_SWITCHED,
    }
)

#: What ``controller.obstacle_sources`` may name: the laser's scan, the depth cameras'
#: virtual scans (depthscan/; services/controller/depth_obstacles.py).
LASER_SOURCE = "laser"
DEPTH_SOURCE = "depth"
OBSTACLE_SOURCES = (LASER_SOURCE, DEPTH_SOURCE)

SERVICE = "controller"
#: Its work loop publishes counters on every pass: its heartbeat (deploy/watchdog.py).
HEARTBEAT = True
#: The operator's e-stop tool's principal: it puts the e-stop and reads the controller's status.
ESTOP_PRINCIPAL = "estop"


def access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    return {
        SERVICE: service_access(
            keys,
            SERVICE,
            keys.cmd_vel(),
            keys.controller_status(),
            # The depth scan stage's output too: the controller reads it only when its
            # settings need depth, but the rules are the shape's, not one config's.
            read=(
                keys.all_detections(),
                keys.scan(),
                keys.estop(),
                keys.all_virtual_scans(),
                keys.remembered_scan(),
                keys.known_floor(),
            ),
            watch=(keys.all_camera_announcements(),),  # its cameras: the announced ones
        )
    }


def estop_access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    return {ESTOP_PRINCIPAL: Access(put=(keys.estop(),), read=(keys.controller_status(),))}


# -- settings -------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True, kw_only=True)
class ControllerSettings:
    """The reaction policy. Speeds in m/s and rad/s, angles in degrees, times in seconds.

    Every camera announced on the bus (common/announce.py, by its source: not the config's) is
    used: a box's bearing is turned into the robot's frame by the ``mount_yaw_deg`` and
    ``hfov_deg`` its camera announces, and targets are chosen among all fresh cameras' boxes;
    a stale camera is ignored, and none fresh is the dead-man stop. Detections of a camera
    not announced are ignored; the target's camera withdrawn is a stop.
    track:  turn towards the most central confident detection of ``target_classes`` (the
            smallest bearing from the robot's heading); drive forward at ``forward_speed``
            only while it is centred: within ``center_tolerance`` (a fraction of the image
            width of the camera that sees it, as an angle from the heading) of straight ahead,
            and while the way ahead is known clear, as in follow mode (below).
            A target beside or behind the robot is never centred: the robot turns in place.
    follow: lock onto the largest detection of ``target_classes[0]`` (by camera and track id,
            so it does not jump to another person) and keep it at ``follow_distance_m``,
            measured from the
            box height (``distance_source = "box"``, for a target ``target_height_m`` tall),
            by the laser in the target's bearing (``"laser"``) or by the depth camera (``"depth"``:
            the horizontal distance from the robot base's centre to the detection's 3D centre,
            its ``x_m``/``z_m`` columns placed by the camera's announced mounting; unknown,
            NaN or absent, means turning only). Forward only while centred and
            while the laser sector of ``sector_width_deg`` straight ahead, and the corridor
            ``robot_width_m`` wide that the body sweeps, are clear beyond ``safety_distance_m``
            plus the room needed to brake. A box cut by the image edge counts as arrived.
            A target unseen for ``target_lost_timeout_s`` is dropped. When it leaves its
            camera's view, the lock passes to a box of its class in another camera within
            ``handover_gate_deg`` of its expected bearing, up to ``handover_window_s`` after it
            was last seen; while it is expected between the cameras' fields of view the robot
            keeps turning towards it (without driving) for that long, and longer while it
            still turns towards a camera's view (at most the half turn ``max_angular`` takes
            more): the camera it turns into then has ``target_lost_timeout_s`` to see it.
            A target dropped (searching) is waited for ``relock_window_s``: its track (its
            camera and track id; the Kalman tracker gives a person back their id after an
            occlusion) is locked again when it shows, and nobody else is locked meanwhile;
            after the window the largest is locked (counted: ``lock_switched``, a lock taken
            on another track after one was lost; ``lock_regained``, the lost one taken back).
            A target held unseen is predicted to go on moving across the world at the rate
            its bearing was moving (smoothed, the robot's own turn taken out; at most
            ``hold_bearing_rate`` rad/s, 0: where it was last seen), for up to
            ``target_lost_timeout_s``: the robot turns after a person who strode out of view.
    Forward safety, in both modes: forward only while the laser sector of ``sector_width_deg``
    straight ahead and the corridor ``robot_width_m`` wide are clear beyond
    ``safety_distance_m`` plus the room needed to brake. A missing scan, or one older than
    ``scan_timeout_s``, means no forward motion (turning in place stays allowed), unless
    ``no_laser`` is set: the robot has no laser, forward motion towards a target in view is
    not checked for obstacles, and every ControllerStatus says so (``no_laser``); a scan that
    does come is still obeyed, and a target out of view is never driven on to without one.
    ``obstacle_sources`` names what must show the way clear: ``"laser"`` (the scan, above),
    ``"depth"`` (a virtual scan made from every announced depth camera's images,
    depthscan/, under the same rules), or both. Each one listed must be
    fresh for forward motion (depth older than ``depth_timeout_s`` is missing, as a scan
    older than ``scan_timeout_s`` is), and every fresh one is obeyed, listed or not. The
    virtual scans are made by the depth scan stage (services/depthscan, which reads these
    ``depth_*`` settings and must run when depth is needed: ``needs_depth``) and read by the
    controller only then, each camera's judged by ``depth_timeout_s``. In a depth image, a
    hole of no readings ``depth_hole_px`` tall or more where the floor should show is
    unknown, never clear (smaller ones are a stereo camera's speckle); one beside a thing
    that fills the bottom of the image, within ``depth_edge_band_px``, is that thing's edge
    (a stereo camera's band of no readings beside a near object). What the depth cameras
    saw is kept in a rolling map ``depth_memory_size_m`` across, in cells
    ``depth_memory_resolution_m`` wide, moved by the controller's own commands
    (depthscan/local_map.py, kept by the stage, which hears cmd_vel): an obstacle or a drop-off
    seen stays until its place is seen clear, and with depth required the robot drives no faster
    than ``depth_creep_speed`` while the corridor ahead within the room it needs to stop has a
    part never seen (at start-up: the camera's blind zone). The map is written at once when it
    gains a hazard, and every ``depth_memory_save_s``, to ``depth_memory_file`` (relative to the
    repo root; empty: ``state/depth-memory-<prefix>.npz``) and a stage that starts within
    ``depth_memory_max_age_s`` of the last write takes back its hazards (a crash, a restart),
    placed as if the robot had gone on with its last command for ``depth_memory_coast_s`` (a
    base's own command timeout).
    Both turn with a PID on the bearing error (rad -> rad/s) and obey the speed and
    acceleration limits. Stale detections (captured or received longer than
    ``detection_timeout_s`` ago) and the e-stop command zero at once, bypassing the
    acceleration limit. The latched e-stop is kept in ``estop_file`` (relative to the repo
    root; empty: ``state/estop-<prefix>.json``), so that it survives every restart; a release
    captured more than ``estop_release_max_age_s`` ago is refused.
    """

    mode: ControllerMode = ControllerMode.FOLLOW
    target_classes: Annotated[tuple[str, ...], Length(1, 100)] = ("person",)
    min_score: Annotated[float, Range(0, 1)] = 0.3
    # A real base: up to 5 m/s (warehouse robots run at 2..3), 10 rad/s, about 1 g of braking.
    # Commands go out at least control_rate_hz times a second: below 1 Hz a base's own
    # command timeout would trip between them. The dead-man (detection_timeout_s) stops the
    # robot within 10 s at the very most.
    control_rate_hz: Annotated[float, Range(1, 1000)] = 20.0
    detection_timeout_s: Annotated[float, Range(0.01, 10)] = 1.0
    scan_timeout_s: Annotated[float, Range(0.01, 10)] = 0.5
    target_lost_timeout_s: Annotated[float, Range(0.01, 60)] = 1.5
    handover_gate_deg: Annotated[float, Range(1, 90)] = 20.0
    handover_window_s: Annotated[float, Range(0.01, 60)] = 3.0
    relock_window_s: Annotated[float, Range(0, 60)] = 3.0
    hold_bearing_rate: Annotated[float, Range(0, 10)] = 1.0
    bearing_kp: Annotated[float, Range(0, 100)] = 1.5
    bearing_ki: Annotated[float, Range(0, 100)] = 0.0
    bearing_kd: Annotated[float, Range(0, 100)] = 0.05
    max_angular: Annotated[float, Range(0.01, 10)] = 1.0
    max_linear: Annotated[float, Range(0.01, 5)] = 0.5
    max_angular_accel: Annotated[float, Range(0.01, 100)] = 3.0
    max_linear_accel: Annotated[float, Range(0.01, 20)] = 1.0
    forward_speed: Annotated[float, Range(0, 5)] = 0.3
    center_tolerance: Annotated[float, Range(0, 1)] = 0.1
    distance_source: DistanceSource = DistanceSource.LASER
    follow_distance_m: Annotated[float, Range(0.1, 20)] = 1.0
    distance_gain: Annotated[float, Range(0, 10)] = 0.6
    target_height_m: Annotated[float, Range(0.01, 10)] = 1.7
    safety_distance_m: Annotated[float, Range(0.01, 10)] = 0.5
    sector_width_deg: Annotated[float, Range(1, 360)] = 30.0
    robot_width_m: Annotated[float, Range(0.05, 5)] = 0.6
    no_laser: bool = False
    obstacle_sources: Annotated[tuple[str, ...], Length(1, 2)] = (LASER_SOURCE,)
    depth_timeout_s: Annotated[float, Range(0.01, 10)] = 0.5
    depth_floor_margin_m: Annotated[float, Range(0.01, 0.15)] = 0.05
    depth_max_height_m: Annotated[float, Range(0.05, 5)] = 1.5
    depth_scan_stride_px: Annotated[int, Range(1, 8)] = 4
    depth_scan_resolution_deg: Annotated[float, Range(0.1, 10)] = 1.0
    depth_hfov_tolerance_deg: Annotated[float, Range(0.1, 30)] = 5.0
    depth_max_pixel_aspect: Annotated[float, Range(1, 2)] = 1.25
    depth_max_pixels: Annotated[int, Range(1, 100_000_000)] = 4_194_304
    # Issue 38: the virtual scan's holes and the depth cameras' short memory.
    depth_hole_px: Annotated[int, Range(1, 100)] = 12
    depth_edge_band_px: Annotated[int, Range(0, 200)] = 24
    depth_creep_speed: Annotated[float, Range(0, 1)] = 0.1
    depth_memory_size_m: Annotated[float, Range(2, 40)] = 8.0
    depth_memory_resolution_m: Annotated[float, Range(0.01, 0.2)] = 0.05
    depth_memory_file: str = ""
    depth_memory_save_s: Annotated[float, Range(0.05, 60)] = 0.5
    depth_memory_max_age_s: Annotated[float, Range(0, 3600)] = 10.0
    depth_memory_coast_s: Annotated[float, Range(0, 10)] = 0.5
    estop_file: str = ""
    estop_release_max_age_s: Annotated[float, Range(0.1, 60)] = 2.0
    counters_period_s: Annotated[float, Range(0.1, 60)] = 1.0
    # -- depth from the announced source only (issue 38) --
    # Depth stamped on this host's boot (its header's boot_id and mono_ns) is read off the
    # controller's own clocks: more than this ahead of them is forged or broken, never a clock
    # offset, and is refused (``depth_future``); other depth keeps stack.clock_tolerance_s.
    depth_future_tolerance_s: Annotated[float, Range(0.001, 1)] = 0.02
    # This many depth frames of one camera older than its held one, within the window: the
    # sign of a second stream on its key (``depth_second_stream``, a WARNING).
    depth_late_warn_count: Annotated[int, Range(1, 1000)] = 3
    depth_late_warn_window_s: Annotated[float, Range(0.1, 60)] = 2.0
    # --

    def __post_init__(self) -> None:
        enum_field(self, "mode", ControllerMode, "controller.mode")
        enum_field(self, "distance_source", DistanceSource, "controller.distance_source")
        check_lengths(self, "controller", ControllerSettings)
        if not all(self.target_classes):
            raise ConfigError(
                f"controller.target_classes must be class names, got {list(self.target_classes)}"
            )
        check_bounds(self, "controller", ControllerSettings)
        if (
            self.no_laser
            and self.mode is ControllerMode.FOLLOW
            and self.distance_source is DistanceSource.LASER
        ):
            raise ConfigError(
                'controller.no_laser = true needs distance_source = "box" in follow mode: '
                "without a laser there is no distance to the target"
            )
        self._check_sources()
        if self.depth_max_height_m <= self.depth_floor_margin_m:
            raise ConfigError(
                f"controller.depth_max_height_m ({self.depth_max_height_m}) must be above "
                f"depth_floor_margin_m ({self.depth_floor_margin_m})"
            )
        if self.forward_speed > self.max_linear:
            raise ConfigError(
                f"controller.forward_speed must be within 0..max_linear ({self.max_linear}), "
                f"got {self.forward_speed}"
            )

    def _check_sources(self) -> None:
        """The obstacle sources: known, each once, and not at odds with ``no_laser``."""
        sources = list(self.obstacle_sources)
        if any(x not in OBSTACLE_SOURCES for x in sources) or len(set(sources)) != len(sources):
            raise ConfigError(
                f"controller.obstacle_sources must name each of {list(OBSTACLE_SOURCES)} at "
                f"most once, got {sources}"
            )
        if self.no_laser and DEPTH_SOURCE in sources:
            raise ConfigError(
                'controller.no_laser = true (forward motion unchecked) contradicts "depth" in '
                "obstacle_sources (checked by the depth camera): for a robot with a depth camera "
                'and no laser set obstacle_sources = ["depth"] and no_laser = false'
            )
        if self.no_laser and self.distance_source is DistanceSource.DEPTH:
            raise ConfigError(
                'controller.no_laser = true with distance_source = "depth": the depth camera '
                'can check the way, set obstacle_sources = ["depth"] and no_laser = false'
            )

    @property
    def needs_depth(self) -> bool:
        """Whether the controller reads the depth cameras' virtual scans (for their
        obstacles): the depth scan stage (services/depthscan) must then run."""
        return self.distance_source is DistanceSource.DEPTH or DEPTH_SOURCE in self.obstacle_sources

    @property
    def laser_required(self) -> bool:
        """Whether forward motion needs a fresh laser scan."""
        return LASER_SOURCE in self.obstacle_sources and not self.no_laser


#: The stack config's tables this service reads (stack/config.py's Config has each).
SETTINGS_TABLES = {"controller": ControllerSettings}
