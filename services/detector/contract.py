"""The detector's contract: its counters and what each worker puts, announces, serves and reads.

Imports only ``common`` and the detection library's settings (perception/settings.py, which
imports only ``common``): the config, the access rules (stack/) and the metrics service read it
without the detector's internals. Each worker (``detector``, ``detector_2``,
``detector_<worker_id>`` ...) counts totals under the plain names and each camera's under
``<name>.<camera>`` (common/counters.py::per_camera) for those in :data:`PER_CAMERA`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Annotated

from common.access import Access, Shape, service_access
from common.counters import BAD_INPUT, COMMON, DROP_VERDICTS
from common.errors import ConfigError
from common.limits import DEFAULT_MAX_FRAME_PIXELS, MAX_IMAGE_SIDE
from common.setting_checks import Length, Range, check_bounds, check_lengths
from perception.settings import DetectorSpec, TrackerParams

#: As common/messages.py's (the contract loads no messages: a unit test checks they agree).
MAX_CAPACITY_HZ = 100_000.0
MAX_ANNOUNCED_PREFIXES = 64

# -- counters --------------------------------------------------------------------------------
FRAMES_IN = "frames_in"  # frames offered: heard on a camera this worker serves
FRAMES_MISSED = "frames_missed"  # gaps in a camera's frame numbering
DROPPED = "dropped"  # frames replaced in the slot by a newer one before detection
FRAMES_OVERSIZE = "frames_oversize"  # over detector.max_frame_pixels
NONFINITE_OUTPUTS = "nonfinite_outputs"  # the model's output was not finite: nothing published
DETECTIONS_OUT = "detections_out"
BATCHES = "batches"  # inference runs (rounds) ...
BATCHED_FRAMES = "batched_frames"  # ... and the frames in them: the mean batch is their ratio
TRACKER_STAMP_JUMPS = "tracker_stamp_jumps"
TRACKER_RESETS = "tracker_resets"
# The pool (gauges: moved by their difference, so they read as the current value).
SERVING = "serving"  # cameras served; per camera 1 while it serves the camera
POOL_MEMBERS = "pool_members"
POOL_LOAD_PERMILLE = "pool_load_permille"  # its cameras' share of every camera's frame rate
POOL_WARNINGS = "pool_warnings"
CAMERAS_GAINED = "cameras_gained"  # hand-overs
CAMERAS_LOST = "cameras_lost"
POOL_RESIGNED = "pool_resigned"  # left the pool on a stalled detection loop
CAPACITY_HZ = "capacity_hz"  # the capacity it announces (frames/s, rounded)
POOL_STRAYS = "pool_strays"  # pool tokens with no worker announcement: ignored
CAPACITY_ANNOUNCED = "capacity_announced"  # re-announcements of a moved capacity
#: Members dropped now for delivering no detections (common/pool_delivery.py), and how many
#: times one was dropped.
POOL_DROPPED = "pool_dropped"
POOL_DROPS = "pool_drops"
#: Announced cameras refused now (over ``max_robot_cameras`` of one robot, or a name whose
#: counter label another camera's already has: common/pool_rule.py's ``admit_cameras``).
CAMERAS_REFUSED = "cameras_refused"
# Attention (services/detector/attention.py): a gauge, per camera 1 while it has priority (in
# all: the cameras with priority), and the frames rounds took for each reason, counted only
# while some camera has priority (the fair rounds count none).
ATTENTION_PRIORITY = "attention_priority"
TAKEN_PRIORITY = "taken_priority"  # a priority camera's frame
TAKEN_FLOOR = "taken_floor"  # a camera due for its floor rate, ahead of the priority ones
TAKEN_SPARE = "taken_spare"  # another camera's, with no priority camera waiting
#: Rounds in which the cameras due for their floor went after the priority ones: the floors
#: over ``attention_floor_share`` of the frames (their bound then no longer holds).
ATTENTION_FLOOR_HELD = "attention_floor_held"
# Depth (services/detector/depth_stage.py): depth frames heard on a depth camera this worker
# serves, and the colour frames of such a camera whose detections got depth columns (paired)
# or went out 2D only (no depth frame within detector.depth_pair_tolerance_ms). Bad depth
# payloads are bad input.
DEPTH_IN = "depth_in"
DEPTH_PAIRED = "depth_paired"
DEPTH_UNPAIRED = "depth_unpaired"
#: Frames whose depth stage raised (a defect): published without depth, logged.
DEPTH_FAILED = "depth_failed"


def taken_for(reason: str) -> str:
    """The counter of frames taken for ``reason`` (services/detector/attention.py)."""
    return f"taken_{reason}"


#: The pool's gauges (set, not counted up).
POOL_GAUGES = (
    SERVING,
    POOL_MEMBERS,
    POOL_LOAD_PERMILLE,
    POOL_WARNINGS,
    CAPACITY_HZ,
    POOL_STRAYS,
    POOL_DROPPED,
    CAMERAS_REFUSED,
)


def frames_judged(verdict: str) -> str:
    """The counter of frames dropped as they leave the slot for ``verdict`` (not fresh)."""
    return f"frames_{verdict}"


_JUDGED = tuple(frames_judged(v) for v in DROP_VERDICTS)

#: Counted for each camera too, as ``<name>.<camera>``.
PER_CAMERA = frozenset(
    {
        FRAMES_IN,
        FRAMES_MISSED,
        DROPPED,
        BAD_INPUT,
        FRAMES_OVERSIZE,
        *_JUDGED,
        NONFINITE_OUTPUTS,
        DETECTIONS_OUT,
        TRACKER_STAMP_JUMPS,
        TRACKER_RESETS,
        SERVING,
        CAMERAS_GAINED,
        CAMERAS_LOST,
        ATTENTION_PRIORITY,
        TAKEN_PRIORITY,
        TAKEN_FLOOR,
        TAKEN_SPARE,
        DEPTH_IN,
        DEPTH_PAIRED,
        DEPTH_UNPAIRED,
        DEPTH_FAILED,
    }
)
#: Every counter a worker publishes (plain names; see PER_CAMERA for the per-camera ones).
COUNTERS = frozenset(
    {
        *COMMON,
        *PER_CAMERA,
        BATCHES,
        BATCHED_FRAMES,
        POOL_MEMBERS,
        POOL_LOAD_PERMILLE,
        POOL_WARNINGS,
        POOL_RESIGNED,
        CAPACITY_HZ,
        POOL_STRAYS,
        CAPACITY_ANNOUNCED,
        POOL_DROPPED,
        POOL_DROPS,
        CAMERAS_REFUSED,
        ATTENTION_FLOOR_HELD,
    }
)


# -- the bus ---------------------------------------------------------------------------------
#: Its work loop publishes counters on every pass: its heartbeat (deploy/watchdog.py).
HEARTBEAT = True


def access(shape: Shape) -> dict[str, Access]:
    """Each worker reads frames and depth images and puts detections, never frames: every
    camera's, as any worker may come to serve any camera (services/detector/pool.py); it reads
    the controller's status too, for the camera that sees the target and the target classes
    (services/detector/attention.py), the robot's commands (its turn, for the tracker:
    services/detector/motion.py), and every camera's detections, whoever puts them: a
    pool member earns its cameras by their detections arriving (common/pool_delivery.py). Its
    tokens are its own only: its health, its pool
    membership, its announcement and its serving tokens under its own name (those of the pool
    under ``detector.pool_prefix``), so that no worker can pose as another, or as many, and
    skew the assignment or its audit. It serves the model's description on each camera's info
    key. A pool serving further robots (``shape.prefixes``) reads each one's frames, depth
    images and detections and puts its detections, and serves its info, on every camera under
    its prefix (their cameras come and go with their announcements), and reads its
    controller's status (attention) and commands (the tracker takes the robot's turn out of
    its predictions: services/detector/motion.py), and puts nothing else of theirs: no
    command."""
    keys, pool = shape.keys, shape.pool_keys()
    robots = shape.other_robots()
    return {
        w: service_access(
            keys,
            w,
            *(keys.detections(c) for c in shape.cameras),
            *(r.all_detections() for r in robots),
            read=(
                keys.all_frames(),
                keys.all_depths(),
                keys.all_detections(),
                keys.controller_status(),
                keys.cmd_vel(),
                *(
                    k
                    for r in robots
                    for k in (
                        r.all_frames(),
                        r.all_depths(),
                        r.all_detections(),
                        r.controller_status(),
                        r.cmd_vel(),
                    )
                ),
            ),
            token=(
                keys.health(w),
                pool.pool_member(w),
                pool.worker_announcements_of(w),
                pool.pool_serving_of(w),
            ),
            serve=(keys.all_detector_info(), *(r.all_detector_info() for r in robots)),
        )
        for w in dict.fromkeys(shape.workers)
    }


# -- settings -------------------------------------------------------------------------------------
#: The most frames one detector round may batch (``detector.max_batch``): one per camera.
MAX_SERVED_BATCH = 32
#: The most depth frames kept per camera to pair from (``detector.depth_buffer``).
MAX_DEPTH_BUFFER = 64
#: ``detector.batch_choice``: measure at start which batch pays, or always fill to max_batch.
BATCH_CHOICES = ("measured", "max")

#: The most detector workers one supervisor starts (``detector.workers``).
MAX_WORKERS = 8
#: ``detector.worker_id``: one key chunk, process, principal and file name, starting with a
#: letter (a digit would read as the n-th worker's number: ``detector_2``) and not ending in
#: ``_<number>`` (the suffix of a host's further workers: ``detector_gpu_2``).
_WORKER_ID = re.compile(r"[a-z](?:[a-z0-9_]{0,22}[a-z0-9])?")
_NUMBERED = re.compile(r"_[0-9]+$")


_PREFIX_CHUNK = re.compile(r"[A-Za-z0-9_.\-]{1,64}")  # as a WorkerAnnouncement's prefixes


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectorSettings(DetectorSpec):
    """The ``[detector]`` table: the detection library's settings, and serving's own.

    Of the library's (perception/settings.py's DetectorSpec, declared and checked there):
    ``model``, ``backend``, ``precision``, ``imgsz``, ``profile``, ``fast_max_ap50_drop``,
    ``calibration_dir`` and ``batch_profile`` say which model to open and how (ModelSpec);
    ``conf``, ``iou``, ``max_det`` and ``classes`` what the Detector keeps of its output
    (DecodeOptions). The library takes these settings as they are: they are its spec.

    ``max_batch`` is the most frames one detection round takes, the newest of each waiting
    camera (docs/detector.md, "Several cameras"): a round never holds more frames than there
    are cameras, so one camera always runs batches of 1. It is 1 by default: on the CPU a batch
    adds no parallelism to a runtime already using every core and costs latency (measured in
    docs/benchmarks.md, "Several cameras on one detector"); raise it on a GPU. Raising it is
    safe: with ``batch_choice`` "measured" the detector times batch 1, 2, 4, ... at start
    (``batch_probe_runs`` runs each) and uses a larger batch only where it saves at least
    ``batch_min_gain`` of the time per image (perception/batching.py); "max" always
    fills rounds up to ``max_batch``.
    A frame captured more than ``max_frame_age_s`` ago, stamped in the future or replayed is
    not detected on (counted, see common/freshness.py). A frame of more than
    ``max_frame_pixels`` (width x height, JPEG or raw) is counted as ``frames_oversize`` and
    dropped before its pixels are decoded.

    The pool (docs/detector.md, "A pool of workers"): ``workers`` detector processes on this
    host divide the cameras between them, with those on other hosts in the same pool (its
    tokens and announcements under ``pool_prefix``; empty: the stack's prefix); 1 (the
    default) is one detector serving every camera. A worker serves the cameras announced
    (CameraAnnouncement) under each robot prefix of ``prefixes`` (empty: the stack's prefix),
    whatever its own config's camera tables say. Each worker announces its capacity, the
    frames per second it detects: ``capacity_hz``, or, when 0, measured at start (after the
    warm-up, ``batch_probe_runs`` timed rounds) and kept current as a moving average (weight
    ``capacity_smoothing`` per round) of its busy rounds' throughput, announced again when it
    moved by more than ``capacity_step`` (a fraction) and at most every
    ``capacity_period_s``. Each worker has one name, its service, process, health token,
    counters, pool id and principal: ``detector``,
    ``detector_2`` ... or, with ``worker_id`` set, ``detector_<id>``, ``detector_<id>_2`` ...
    (common/settings.py::detector_service). Names must differ across hosts, so on several hosts
    give each its own ``worker_id`` (``"robot1"``). ``pool_balance`` is the slack over a
    share of the cameras' frame rate in proportion to its capacity that a worker may take
    before a camera goes to its next choice (services/detector/pool.py). A worker whose
    detection loop has not passed for ``pool_stall_s`` leaves the pool (its cameras go to
    the others) until it runs again.
    A member earns its cameras by delivering (common/pool_delivery.py): one whose cameras all
    get no detections for ``pool_deliver_s`` after it was given them is dropped from the
    assignment for ``pool_readmit_s`` (doubled at each further drop), whatever capacity it
    claims. One robot may have at most ``max_robot_cameras`` cameras served; the rest are
    refused, as is a camera whose counter label another's has (common/pool_rule.py).
    What is wrong with the pool (a member that serves nothing or delivers nothing, a camera
    nobody or two serve or whose detections do not come, a name held twice) is a warning once
    it has lasted ``pool_alarm_s`` (common/pool_audit.py).
    A pool token with no announcement is no member (ignored; counted as ``pool_strays``).

    Attention (docs/detector.md, "Attention"; services/detector/attention.py): with
    ``attention`` on, when the cameras send more than the worker detects, the camera holding
    the controller's lock and those that saw one of its target classes within
    ``attention_hold_s`` go first, and every other camera is still detected on at least
    ``attention_floor_hz`` times a second (within a round or two), as long as the floors take
    at most ``attention_floor_share`` of the frames (beyond, the priority cameras go first).
    Off, or with no camera prioritised, the rounds are the fair rotation.

    Depth (docs/detector.md, "Depth"; services/detector/depth_stage.py): for a camera announced
    with depth, each colour frame is paired with the depth frame of its camera whose stamp is
    nearest, within ``depth_pair_tolerance_ms``; the last ``depth_buffer`` depth frames of each
    camera are kept to pair from; a frame whose depth frame has not come when its detections are
    built waits up to ``depth_wait_ms`` for it (only when its camera's last frame paired). A box
    needs at least ``depth_min_valid_pixels`` valid depth pixels in its region, and at least
    ``depth_min_valid_fraction`` of it, else it gets NaN (unknown) in every depth column
    (perception/depth.py's DepthParams).
    """

    max_batch: Annotated[int, Range(1, MAX_SERVED_BATCH)] = 1
    batch_choice: str = "measured"
    batch_min_gain: Annotated[float, Range(0, 0.9)] = 0.2
    batch_probe_runs: Annotated[int, Range(1, 20)] = 3
    max_frame_age_s: Annotated[float, Range(0.01, 60)] = 1.0
    counters_period_s: Annotated[float, Range(0.1, 60)] = 1.0
    # JPEG header or raw size
    max_frame_pixels: Annotated[int, Range(1, MAX_IMAGE_SIDE * MAX_IMAGE_SIDE)] = (
        DEFAULT_MAX_FRAME_PIXELS
    )
    workers: Annotated[int, Range(1, MAX_WORKERS)] = 1
    worker_id: str = ""
    pool_balance: Annotated[float, Range(1, 4)] = 1.0
    pool_stall_s: Annotated[float, Range(1, 60)] = 5.0
    pool_alarm_s: Annotated[float, Range(1, 600)] = 10.0
    pool_deliver_s: Annotated[float, Range(0.5, 600)] = 4.0
    pool_readmit_s: Annotated[float, Range(1, 3600)] = 30.0
    max_robot_cameras: Annotated[int, Range(1, 1024)] = 16
    pool_prefix: str = ""
    prefixes: Annotated[tuple[str, ...], Length(0, MAX_ANNOUNCED_PREFIXES)] = ()
    capacity_hz: Annotated[float, Range(0, MAX_CAPACITY_HZ)] = 0.0
    capacity_step: Annotated[float, Range(0.01, 10)] = 0.25
    capacity_period_s: Annotated[float, Range(0.5, 3600)] = 10.0
    capacity_smoothing: Annotated[float, Range(0.01, 1)] = 0.05
    attention: bool = True
    attention_floor_hz: Annotated[float, Range(0.05, 100)] = 1.5
    attention_floor_share: Annotated[float, Range(0.05, 1)] = 0.5
    attention_hold_s: Annotated[float, Range(0, 60)] = 2.0
    depth_pair_tolerance_ms: Annotated[float, Range(0, 1000)] = 20.0
    depth_buffer: Annotated[int, Range(1, MAX_DEPTH_BUFFER)] = 4
    depth_wait_ms: Annotated[float, Range(0, 200)] = 10.0
    depth_min_valid_pixels: Annotated[int, Range(1, MAX_IMAGE_SIDE * MAX_IMAGE_SIDE)] = 20
    depth_min_valid_fraction: Annotated[float, Range(0, 1)] = 0.05

    def __post_init__(self) -> None:
        DetectorSpec.__post_init__(self)
        check_bounds(self, "detector", DetectorSettings)
        check_lengths(self, "detector", DetectorSettings)
        if self.batch_choice not in BATCH_CHOICES:
            raise ConfigError(
                f"detector.batch_choice must be one of {', '.join(BATCH_CHOICES)}, "
                f"got {self.batch_choice!r}"
            )
        if self.worker_id and (
            not _WORKER_ID.fullmatch(self.worker_id) or _NUMBERED.search(self.worker_id)
        ):
            raise ConfigError(
                f"detector.worker_id {self.worker_id!r} must be 1..24 of a-z, 0-9 and _, start "
                "with a letter and not end in _<number>: it names the workers (detector_<id>, "
                "detector_<id>_2 ...), their keys, processes and principals"
            )
        named = [("prefixes", p) for p in self.prefixes]
        if self.pool_prefix:
            named.append(("pool_prefix", self.pool_prefix))
        for what, prefix in named:
            if not all(_PREFIX_CHUNK.fullmatch(chunk) for chunk in prefix.split("/")):
                raise ConfigError(
                    f"detector.{what} {prefix!r} must be a key prefix: '/'-separated words of "
                    "letters, digits, '_', '-', '.'"
                )
        if len(set(self.prefixes)) != len(self.prefixes):
            raise ConfigError(f"detector.prefixes names one twice: {list(self.prefixes)}")
        if self.attention and self.pool_deliver_s <= 1 / self.attention_floor_hz:
            raise ConfigError(
                f"detector.pool_deliver_s ({self.pool_deliver_s} s) must be above the attention "
                f"floor's period (1 / detector.attention_floor_hz = "
                f"{1 / self.attention_floor_hz:.2f} s): an empty camera's worker would be "
                "dropped from the pool for delivering between its floor's detections"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class TrackerSettings(TrackerParams):
    """The ``[tracker]`` table: the detector's multi-object tracker, which gives Detections
    their track ids. Its thresholds are the library's (perception/settings.py's TrackerParams,
    declared and checked there); ``enabled`` is the service's to read."""

    enabled: bool = True


#: The stack config's tables this service reads (stack/config.py's Config has each).
SETTINGS_TABLES = {"detector": DetectorSettings, "tracker": TrackerSettings}
