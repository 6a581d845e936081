"""The stack's shared vocabularies and the shapes of the JSON it writes, in one module.

Enums name what used to be bare strings (a controller mode, a state, a backend); each is a
``StrEnum``, so it equals its string on the wire, in TOML and in JSON. The ``TypedDict``s are
the contracts of the JSON answers (the metrics query, a scenario's figures, a benchmark, a
recorded session): the writer builds them, every reader reads them through these types.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Any, NotRequired, TypedDict


class ControllerMode(StrEnum):
    TRACK = "track"  # turn towards the most central target; forward while centred
    FOLLOW = "follow"  # lock onto one target and keep a distance


class ControllerState(StrEnum):
    """What the controller is doing; ControllerStatus.state carries it."""

    STALE = "stale"  # no fresh detections: zero (dead-man)
    ESTOP = "estop"  # the e-stop is latched: zero
    SEARCHING = "searching"  # no target in view: zero
    HOLDING = "holding"  # target briefly unseen: keep the last aim
    TURNING = "turning"  # target off-centre: turn only
    TRACKING = "tracking"  # track mode, centred: forward
    FOLLOWING = "following"  # follow mode, centred and clear: forward
    BLOCKED = "blocked"  # something ahead, or no scan: turn only
    ARRIVED = "arrived"  # at the follow distance: turn only
    FAULT = "fault"  # a non-finite command was computed: zero
    STOPPED = "stopped"  # shutting down: zero


class DistanceSource(StrEnum):
    BOX = "box"  # from the box height and the target's known height
    LASER = "laser"  # the laser's range in the target's bearing
    DEPTH = "depth"  # the depth camera's: the target's ``distance_m`` column (perception/depth.py)


class BackendName(StrEnum):
    ONNX = "onnx"  # ONNX Runtime on the CPU
    TENSORRT = "tensorrt"
    CUDA = "cuda"  # our ONNX interpreter on PyTorch CUDA
    OPENVINO = "openvino"  # OpenVINO on the CPU (an optional extra)
    AUTO = "auto"  # tensorrt, then cuda, then openvino (CPUs with VNNI or AMX), then onnx


# --- The JSON the stack writes ------------------------------------------------------------------
# Latency statistics per stage: p50, p95, p99, mean and count (common to the query and reports).
LatencyStats = dict[str, dict[str, float]]


class TimelineSeries(TypedDict):
    """Per-period figures over a run: ``t`` in seconds, the rest one value per period."""

    period_s: float
    t: list[float]
    fps: list[float]
    offered_fps: list[float]
    dropped: list[float]
    detections_per_frame: list[float]


class CameraMetrics(TypedDict):
    """One camera's figures in the metrics answer (services/metrics/cameras.py): its frames'
    FPS, totals and latency, as the top level has them for every camera together; the drops
    and frames offered from its worker's ``dropped.<cam>`` and ``frames_in.<cam>``; the worker
    that serves it (``served_by``, the service counting ``frames_in.<cam>``) and that worker's
    mean batch over the window; every ``<service>.<name>.<cam>`` counter as
    ``<service>.<name>``; the depth images its worker took (``depth_frames``, from
    ``depth_in.<cam>``) and its colour frames with no depth in time (``depth_unpaired``;
    both absent from answers made before depth)."""

    fps: float
    frames: int
    detections: int
    detections_per_frame: float
    latency_ms: LatencyStats
    dropped_frames: int
    frames_offered: int
    drop_rate: float
    drop_rate_total: float
    served_by: str
    batch_mean: float
    counters: dict[str, int]
    duplicate_detections: NotRequired[int]
    depth_frames: NotRequired[int]
    depth_unpaired: NotRequired[int]


class WorkerMetrics(TypedDict):
    """One detector worker of the pool in the metrics answer (services/metrics/pool.py): whether
    its pool token is live (``false`` once it has gone: exited, killed, or hung past Zenoh's
    lease) and the cameras its serving tokens name; from its counters, their share of every
    camera's frame rate (``load``, 0..1), the live workers it counts, its hand-overs since it
    started, and how long ago its counters came (a gone worker's last word stays). A pool
    worker serving this robot whose counters it does not hear (a shared GPU box's) is listed
    too, from its tokens and announcement."""

    live: bool
    cameras: list[str]
    load: float
    members: int
    cameras_gained: int
    cameras_lost: int
    reported_s_ago: float
    #: As it announces itself to the pool (absent while no announcement is heard): the frames
    #: per second it detects, and the robots (key prefixes) it serves.
    capacity_hz: NotRequired[float]
    robots: NotRequired[list[str]]
    #: Where ``load`` comes from: "counters" (its own, as this robot hears them), or
    #: "cameras" for a worker whose counters this robot does not hear (another host's, under
    #: its own prefix: a shared GPU box): this robot's cameras it serves, their announced
    #: frame rate over its capacity; ``members`` and the hand-overs are then 0 and
    #: ``reported_s_ago`` -1.
    load_from: NotRequired[str]


class AnnouncedCamera(TypedDict):
    """A camera as its source announces it (common/messages.py ``CameraAnnouncement``), in the
    metrics answer's ``cameras_announced``: its frames' size (0x0 while unknown), rate, where
    it looks on the robot, its field of view, its frames' frame id and what announces it;
    whether it publishes depth too, and where it stands on the robot (metres forward, left and
    above the floor; the last four absent from answers made before depth)."""

    width: int
    height: int
    rate_hz: float
    mount_yaw_deg: float
    hfov_deg: float
    frame_id: str
    source: str
    depth: NotRequired[bool]
    mount_x_m: NotRequired[float]
    mount_y_m: NotRequired[float]
    mount_height_m: NotRequired[float]


class MetricsAnswer(TypedDict):
    """The metrics service's answer to a query (``zstack query``), and a session's summary.

    The top-level figures are every camera's together (with one camera, that camera's);
    ``cameras`` has each announced camera's, in the order they were first announced (absent
    from answers recorded before several cameras existed); ``cameras_announced`` what each
    camera's source announces of it now (absent from older answers). ``workers`` has each
    detector worker's (the pool), and
    ``duplicate_detections`` counts frames detected twice (by two workers during a hand-over);
    ``pool_warnings`` says what has been wrong with the pool for ``detector.pool_alarm_s``
    (common/pool_audit.py). ``warnings`` names settings that work against each other on this
    machine, each with its figures and fixes (services/metrics/advice.py; absent from older
    answers). ``depth_frames``: the depth images the detector workers took (their
    ``depth_in``), ``depth_unpaired``: colour frames of a depth camera that found no depth
    image within ``detector.depth_pair_tolerance_ms`` (2D detections only); the depth stage's
    time is ``latency_ms["depth"]`` (absent from answers made before depth).
    """

    stamp_ns: int
    window_s: float
    fps: float
    frames: int
    detections: int
    detections_per_frame: float
    dropped_frames: int
    latency_ms: LatencyStats
    counters: dict[str, int]
    class_counts: dict[str, int]
    drop_rate: float
    drop_rate_total: float
    frames_offered: int
    timeline: TimelineSeries
    cameras: NotRequired[dict[str, CameraMetrics]]
    cameras_announced: NotRequired[dict[str, AnnouncedCamera]]
    workers: NotRequired[dict[str, WorkerMetrics]]
    duplicate_detections: NotRequired[int]
    pool_warnings: NotRequired[list[str]]
    warnings: NotRequired[dict[str, str]]
    depth_frames: NotRequired[int]
    depth_unpaired: NotRequired[int]


class _SessionCore(TypedDict):
    version: int
    created: str
    duration_s: float
    detector: dict[str, str]
    summary: MetricsAnswer
    latency_samples_ms: dict[str, list[float]]


class Session(_SessionCore, total=False):
    """A recorded run (``zstack report`` writes it as session.json and reads it back); a
    recording made live also says how the stack was set up and on what machine."""

    config: dict[str, Any]
    machine: dict[str, Any]
    metrics_service: dict[str, Any] | None
    supervisor_exit_code: int | None
    benchmarks: list[BackendBenchmark]  # added by ``report --benchmark FILE``


class DetectorInfo(TypedDict):
    """The detector's answer on ``<prefix>/detector/<camera>/info``.

    ``variant`` is what runs, ``backend:precision:input size`` (e.g. ``onnx:int8:480``);
    ``note`` says why it differs from what was asked (an INT8 model that could not be built,
    the fast profile's choice), else "".
    """

    model: str
    classes: list[str]
    backend: str
    device: str
    precision: str
    variant: str
    note: str


class DepthError(TypedDict):
    """The live depth figures of a run (``zstack scenario NAME --json``'s ``depth_error``)."""

    rows: int  # matched person detections with a depth
    unknown: int  # matched person detections without one
    median_pct: float  # median |horizontal range error| as % of the true range
    p95_pct: float
    median_signed_m: float  # the median signed error (estimate - truth), metres
    range_m: tuple[float, float]  # the true ranges' span


class ScenarioResult(TypedDict, total=False):
    """A scenario's figures (``zstack scenario NAME --json``); see tools/scenarios/score.py."""

    success: bool
    reason: str
    scenario: str
    mode: str  # the controller's
    world: str  # the simulator's world and faults: "world=hard faults=..." (services/sim/worlds.py)
    duration_s: float
    time_to_reach_s: float | None
    final_distance_m: float | None
    min_clearance_m: float | None
    min_edge_clearance_m: float | None
    mean_bearing_error_deg: float | None
    stale_commands: int
    commands: int
    nonzero_commands: int
    stop_after_kill_s: float | None
    distance_travelled_m: float
    final_bearing_deg: float | None
    frames_per_camera: dict[str, int]
    detections_per_camera: dict[str, int]
    seen_per_camera: dict[str, int]
    moving_at_kill: bool
    checks: dict[str, bool]
    log: str
    supervisor_exit_code: int | None
    depth_error: DepthError  # with depth columns: the detections' range against the truth


class BackendInfo(TypedDict):
    name: str
    device: str
    precision: str
    threads: int | None


class BackendBenchmark(TypedDict, total=False):
    """One backend's figures in ``zstack benchmark --json``."""

    p50_ms: dict[str, float]
    p95_ms: dict[str, float]
    fps: float
    bare_run_p50_ms: float
    ratio_to_bare_run: float
    pre_post_fraction_of_inference: float
    backend: BackendInfo
    agreement: dict[str, float]
    machine: dict[str, Any]  # where it ran


class BenchmarkReport(BackendBenchmark, total=False):
    """``zstack benchmark --json``: the first backend's figures at the top level, every
    backend's under ``backends``, and what they were measured on."""

    runs: int
    warmup: int
    model: dict[str, Any]
    image: dict[str, Any]
    agreement_reference: dict[str, Any]
    backends: dict[str, BackendBenchmark]
