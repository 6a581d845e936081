"""Settings of perception: the camera, the detector and its tracker (tables of stack.toml).

Re-exported by common/settings.py, where the whole Config is assembled.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import ClassVar

from common.contracts import BackendName
from common.errors import ConfigError
from common.limits import MAX_DETECTIONS, MAX_IMAGE_SIDE
from common.setting_checks import Bounds, check_bounds, check_lengths, enum_field

#: The most class names a model may have (LVIS has 1203; COCO 80, Open Images 601).
MAX_CLASSES = 2000
#: The largest TensorRT batch an engine is built for (``detector.batch_profile``).
MAX_BATCH = 64
#: The most frames one detector round may batch (``detector.max_batch``): one per camera.
MAX_SERVED_BATCH = 32
#: ``detector.batch_choice``: measure at start which batch pays, or always fill to max_batch.
BATCH_CHOICES = ("measured", "max")

#: The most detector workers one supervisor starts (``detector.workers``).
MAX_WORKERS = 8
#: ``detector.worker_id``: one key chunk, process, principal and file name, starting with a
#: letter (a digit would read as the n-th worker's number: ``detector_2``) and not ending in
#: ``_<number>`` (the suffix of a host's further workers: ``detector_gpu_2``).
_WORKER_ID = re.compile(r"[a-z](?:[a-z0-9_]{0,22}[a-z0-9])?")
_NUMBERED = re.compile(r"_[0-9]+$")

#: The detector's default pixel budget per frame: 2**25, 32 Mpx. It admits every real camera
#: up to 8K UHD (7680x4320, 33.2 Mpx) and 4096x4096 inspection cameras, and bounds one decoded
#: BGR frame to 96 MiB, where a 16384x16384 JPEG header (the largest a Frame may claim)
#: would make the decoder allocate 768 MiB and more.
DEFAULT_MAX_FRAME_PIXELS = 1 << 25


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraSettings:
    """The frame source.

    ``source`` is one of: ``sample:<name>`` (a scikit-image photo: astronaut, cameraman, chelsea,
    coffee, rocket, motorcycle), a path to an image (repeated), a folder of images (looped), a
    video file (looped when ``loop``), ``device:<index or /dev/videoN>`` (webcam / V4L2), or a
    network stream's URL (``rtsp://``, ``rtsps://``, ``http(s)://``, ``rtmp://``, ``udp://``,
    ``tcp://``, ``srt://``; read by OpenCV's FFmpeg).
    ``resize`` is (width, height), or (0, 0) to keep the source size. ``jpeg_quality`` 0 sends
    raw bgr8; 1..100 sends JPEG at that quality. ``hfov_deg`` is the horizontal field of view,
    which turns a pixel column into a bearing (the controller and the simulator use it).
    ``mount_yaw_deg`` is where the camera looks on the robot, counter-clockwise from the robot's
    forward axis (front 0, left 90, rear 180 or -180): the controller turns a bearing in the
    image into one in the robot's frame with it, and the simulator renders with it.
    A device or stream that gave frames and then stops (unplugged, reset) is reopened every
    ``reopen_period_s`` until it gives frames again (services/camera/reopen.py); one that gives
    none at start-up stops the camera with one line.
    """

    source: str = "sample:cameraman"
    rate_hz: float = 10.0
    resize: tuple[int, int] = (0, 0)
    jpeg_quality: int = 0
    frame_id: str = "camera"
    loop: bool = True
    hfov_deg: float = 60.0
    mount_yaw_deg: float = 0.0
    reopen_period_s: float = 1.0

    BOUNDS: ClassVar[Bounds] = {
        "rate_hz": (0.1, 1000),
        "jpeg_quality": (0, 100),
        "hfov_deg": (1, 179),
        "mount_yaw_deg": (-180, 180),
        "reopen_period_s": (0.05, 60),
    }

    def __post_init__(self) -> None:
        check_bounds(self, "camera", self.BOUNDS)
        if (
            min(self.resize) < 0
            or max(self.resize) > MAX_IMAGE_SIDE
            or (0 in self.resize and self.resize != (0, 0))
        ):
            raise ConfigError(
                f"camera.resize must be [w, h] within 1..{MAX_IMAGE_SIDE} or [0, 0], "
                f"got {list(self.resize)}"
            )


MIN_IMGSZ, MAX_IMGSZ = 160, 1280
PROFILES = ("default", "fast")


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectorSettings:
    """The model, its backend and the post-processing thresholds.

    ``model`` empty means the default COCO model (fetched at setup). ``backend`` is onnx,
    tensorrt, cuda, openvino or auto (auto picks tensorrt, then cuda, then openvino on Intel
    CPUs with VNNI/AMX, then onnx: docs/detector.md). ``precision`` empty leaves the backend's
    default (fp32 on the CPU, fp16 on a GPU); GPU backends take fp32 or fp16, TensorRT also
    int8; onnx and openvino take fp32 or int8 (an INT8 model quantized here, calibrated on real
    photos plus ``calibration_dir``'s, and cached beside the model: docs/detector.md). ``imgsz``
    is the input size: 0 keeps the model's own; another multiple of 32 (160..1280) rebuilds the
    default model at that size, and must equal a named model's own size. ``profile`` "fast"
    picks the fastest (backend, precision, imgsz) variant whose AP50 on the labelled photos is
    at most ``fast_max_ap50_drop`` below FP32 at 640, overriding backend, precision and imgsz.
    ``max_batch`` is the most frames one detection round takes, the newest of each waiting
    camera (docs/detector.md, "Several cameras"): a round never holds more frames than there
    are cameras, so one camera always runs batches of 1. It is 1 by default: on the CPU a batch
    adds no parallelism to a runtime already using every core and costs latency (measured in
    docs/benchmarks.md, "Several cameras on one detector"); raise it on a GPU. Raising it is
    safe: with ``batch_choice`` "measured" the detector times batch 1, 2, 4, ... at start
    (``batch_probe_runs`` runs each) and uses a larger batch only where it saves at least
    ``batch_min_gain`` of the time per image (perception/batching.py); "max" always
    fills rounds up to ``max_batch``.
    ``batch_profile`` is the (min, opt, max) batch a TensorRT engine is built for; left at
    (1, 1, 1), the engine is built for 1..the served batch instead.
    A frame captured more than ``max_frame_age_s`` ago, stamped in the future or replayed is
    not detected on (counted, see common/freshness.py). A frame of more than
    ``max_frame_pixels`` (width x height, JPEG or raw) is counted as ``frames_oversize`` and
    dropped before its pixels are decoded.

    Post-processing, which the Detector (perception/pipeline.py) reads from here:
    ``conf`` is the least score kept (objectness x class score for YOLOv5-style models);
    ``iou`` the overlap above which a lower-scored box of the same class is suppressed;
    ``max_det`` caps detections per image (300 as in Ultralytics; the stack's config sets its
    own); ``classes`` keeps only those class names, and empty keeps every class.

    The pool (docs/detector.md, "A pool of workers"): ``workers`` detector processes on this
    host divide the cameras between them, with those on other hosts that share the key
    prefix; 1 (the default) is one detector serving every camera. Each worker has one name, its
    service, process, health token, counters, pool id and principal: ``detector``,
    ``detector_2`` ... or, with ``worker_id`` set, ``detector_<id>``, ``detector_<id>_2`` ...
    (common/settings.py::detector_service). Names must differ across hosts, so on several hosts
    give each its own ``worker_id`` (``"robot1"``). ``pool_balance`` is the slack over an
    even share of the cameras' pixel rate that a worker may take before a camera goes to its
    next choice (services/detector/pool.py). A worker whose detection loop has not passed
    for ``pool_stall_s`` leaves the pool (its cameras go to the others) until it runs again.
    What is wrong with the pool (a member that serves nothing, a camera nobody or two serve, a
    name held twice) is a warning once it has lasted ``pool_alarm_s`` (common/pool_audit.py).
    """

    model: str = ""
    backend: BackendName = BackendName.ONNX
    precision: str = ""
    batch_profile: tuple[int, int, int] = (1, 1, 1)
    max_batch: int = 1
    batch_choice: str = "measured"
    batch_min_gain: float = 0.2
    batch_probe_runs: int = 3
    conf: float = 0.25
    iou: float = 0.45
    max_det: int = 300
    classes: tuple[str, ...] = ()
    max_frame_age_s: float = 1.0
    counters_period_s: float = 1.0
    max_frame_pixels: int = DEFAULT_MAX_FRAME_PIXELS
    imgsz: int = 0
    calibration_dir: str = ""
    profile: str = "default"
    fast_max_ap50_drop: float = 0.01
    workers: int = 1
    worker_id: str = ""
    pool_balance: float = 1.0
    pool_stall_s: float = 5.0
    pool_alarm_s: float = 10.0

    BOUNDS: ClassVar[Bounds] = {
        "batch_profile": (1, MAX_BATCH),
        "max_batch": (1, MAX_SERVED_BATCH),
        "batch_min_gain": (0, 0.9),
        "batch_probe_runs": (1, 20),
        "conf": (0, 1),
        "iou": (0, 1),
        "max_det": (1, MAX_DETECTIONS),
        "max_frame_age_s": (0.01, 60),
        "counters_period_s": (0.1, 60),
        "max_frame_pixels": (1, MAX_IMAGE_SIDE * MAX_IMAGE_SIDE),  # JPEG header or raw size
        "imgsz": (0, MAX_IMGSZ),  # 0 = the model's own; else a multiple of 32, checked below
        "fast_max_ap50_drop": (0, 1),
        "workers": (1, MAX_WORKERS),
        "pool_balance": (1, 4),
        "pool_stall_s": (1, 60),
        "pool_alarm_s": (1, 600),
    }
    LENGTHS: ClassVar[Bounds] = {"classes": (0, MAX_CLASSES)}

    def __post_init__(self) -> None:
        check_bounds(self, "detector", self.BOUNDS)
        check_lengths(self, "detector", self.LENGTHS)
        if self.imgsz != 0 and (self.imgsz % 32 or not MIN_IMGSZ <= self.imgsz <= MAX_IMGSZ):
            raise ConfigError(
                f"detector.imgsz must be 0 (the model's own) or a multiple of 32 within "
                f"{MIN_IMGSZ}..{MAX_IMGSZ}, got {self.imgsz}"
            )
        if self.profile not in PROFILES:
            raise ConfigError(
                f"detector.profile must be one of {', '.join(PROFILES)}, got {self.profile!r}"
            )
        enum_field(self, "backend", BackendName, "detector.backend")
        if self.batch_choice not in BATCH_CHOICES:
            raise ConfigError(
                f"detector.batch_choice must be one of {', '.join(BATCH_CHOICES)}, "
                f"got {self.batch_choice!r}"
            )
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
        if self.worker_id and (
            not _WORKER_ID.fullmatch(self.worker_id) or _NUMBERED.search(self.worker_id)
        ):
            raise ConfigError(
                f"detector.worker_id {self.worker_id!r} must be 1..24 of a-z, 0-9 and _, start "
                "with a letter and not end in _<number>: it names the workers (detector_<id>, "
                "detector_<id>_2 ...), their keys, processes and principals"
            )
        if not all(self.classes):
            raise ConfigError(
                f"detector.classes must be non-empty class names, got {list(self.classes)}"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class TrackerSettings:
    """The detector's multi-object tracker, which gives Detections their track ids.

    ``high_score`` starts a track, ``low_score`` may only extend one, ``iou`` is the least
    overlap with a track's predicted box, and a track unseen for ``max_age_s`` is dropped.
    A frame whose stamp moved by more than ``max_stamp_jump_s`` beyond the time that really
    passed between arrivals (or went back) is ignored, not allowed to age every track out;
    after ``jumps_before_reset`` such frames in a row the stamps are believed and the tracks
    restart (a camera clock that really stepped). Only frames from another host are checked:
    a frame from this host is tracked on its monotonic stamp, which cannot step
    (perception/tracker.py). ``enabled`` is the service's to read.
    """

    enabled: bool = True
    high_score: float = 0.4
    low_score: float = 0.15
    iou: float = 0.25
    max_age_s: float = 1.0
    max_stamp_jump_s: float = 0.5
    jumps_before_reset: int = 3

    BOUNDS: ClassVar[Bounds] = {
        "high_score": (0, 1),
        "low_score": (0, 1),
        "iou": (0, 1),
        "max_age_s": (0.01, 60),
        "max_stamp_jump_s": (0.01, 60),
        "jumps_before_reset": (1, 1000),
    }

    def __post_init__(self) -> None:
        check_bounds(self, "tracker", self.BOUNDS)
        if self.low_score > self.high_score:
            raise ConfigError("tracker.low_score must not be above tracker.high_score")
