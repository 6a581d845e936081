"""The detection library's own settings: which model to run and how, how to read its output,
and the tracker's thresholds. Each is checked when made, with one line naming the setting.

    ModelSpec       model, backend, precision, input size, profile, calibration (and the
                    batch shapes a TensorRT engine is built for): what variants.py, loading.py
                    and preparing.py turn into the file a backend loads
    DecodeOptions   conf, iou, max_det, classes: what the Detector keeps of a model's output
    DetectorSpec    both: what opening a Detector takes
    TrackerParams   the tracker's thresholds (tracker.py)

The detector service's settings (services/detector/contract.py) are these plus its own, as
the ``[detector]`` and ``[tracker]`` tables of the stack config: the names below are the keys
users write there, and the lines the checks raise name them so (``detector.conf``).

Imports only ``common``, and nothing heavy: the stack's config reads it through the contract.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Annotated

from common.contracts import BackendName
from common.errors import ConfigError
from common.limits import MAX_DETECTIONS
from common.setting_checks import Length, Range, check_bounds, check_lengths, enum_field

#: The most class names a model may have (LVIS has 1203; COCO 80, Open Images 601).
MAX_CLASSES = 2000
#: The largest TensorRT batch an engine is built for (``detector.batch_profile``).
MAX_BATCH = 64
MIN_IMGSZ, MAX_IMGSZ = 160, 1280
PROFILES = ("default", "fast")
PRECISIONS = ("", "fp32", "fp16", "int8")


@dataclass(frozen=True, kw_only=True)
class ModelSpec:
    """Which model to run, on which backend, at which precision and input size.

    ``model`` empty means the default COCO model (fetched at setup). ``backend`` is onnx,
    tensorrt, cuda, openvino or auto (auto picks tensorrt, then cuda, then openvino on Intel
    CPUs with VNNI/AMX, then onnx: docs/detector.md). ``precision`` empty leaves the backend's
    default (fp32 on the CPU, fp16 on a GPU); GPU backends take fp32 or fp16, TensorRT also
    int8; onnx and openvino take fp32 or int8 (an INT8 model quantized ahead of serving,
    calibrated on real photos plus ``calibration_dir``'s, and cached beside the model:
    docs/detector.md). ``imgsz`` is the input size: 0 keeps the model's own; another multiple
    of 32 (160..1280) rebuilds the default model at that size, and must equal a named model's
    own size. ``profile`` "fast" picks the fastest (backend, precision, imgsz) variant whose
    AP50 on the labelled photos is at most ``fast_max_ap50_drop`` below FP32 at 640, overriding
    backend, precision and imgsz. ``batch_profile`` is the (min, opt, max) batch a TensorRT
    engine is built for; left at (1, 1, 1), the engine is built for 1..the served batch instead.
    """

    model: str = ""
    backend: BackendName = BackendName.ONNX
    precision: str = ""
    batch_profile: Annotated[tuple[int, int, int], Range(1, MAX_BATCH)] = (1, 1, 1)
    # 0 = the model's own; else a multiple of 32, checked below
    imgsz: Annotated[int, Range(0, MAX_IMGSZ)] = 0
    calibration_dir: str = ""
    profile: str = "default"
    fast_max_ap50_drop: Annotated[float, Range(0, 1)] = 0.01

    def __post_init__(self) -> None:
        check_bounds(self, "detector", ModelSpec)
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
        if self.precision not in PRECISIONS:
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


@dataclass(frozen=True, kw_only=True)
class DecodeOptions:
    """What the Detector (pipeline.py) keeps of a model's output.

    ``conf`` is the least score kept (objectness x class score for YOLOv5-style models);
    ``iou`` the overlap above which a lower-scored box of the same class is suppressed;
    ``max_det`` caps detections per image (100; ``zstack evaluate`` asks for Ultralytics' 300);
    ``classes`` keeps only those class names, and empty keeps every class.
    """

    conf: Annotated[float, Range(0, 1)] = 0.25
    iou: Annotated[float, Range(0, 1)] = 0.45
    max_det: Annotated[int, Range(1, MAX_DETECTIONS)] = 100
    classes: Annotated[tuple[str, ...], Length(0, MAX_CLASSES)] = ()

    def __post_init__(self) -> None:
        check_bounds(self, "detector", DecodeOptions)
        check_lengths(self, "detector", DecodeOptions)
        if not all(self.classes):
            raise ConfigError(
                f"detector.classes must be non-empty class names, got {list(self.classes)}"
            )


@dataclass(frozen=True, kw_only=True)
class DetectorSpec(DecodeOptions, ModelSpec):
    """A model to open and how to read its output: what opening a Detector takes (its fields
    in that order: the model's, then the decode options)."""

    def __post_init__(self) -> None:
        ModelSpec.__post_init__(self)
        DecodeOptions.__post_init__(self)


class TrackerKind(StrEnum):
    """Which tracker (``tracker.kind``)."""

    IOU = "iou"  # perception/tracker.py: greedy IoU, constant-velocity corners
    KALMAN = "kalman"  # perception/kalman_tracker.py: Kalman, ego-rotation, re-identification


@dataclass(frozen=True, slots=True, kw_only=True)
class TrackerParams:
    """The tracker's thresholds (tracker.py).

    ``high_score`` starts a track, ``low_score`` may only extend one, ``iou`` is the least
    overlap with a track's predicted box, and a track unseen for ``max_age_s`` is dropped.
    A frame whose stamp moved by more than ``max_stamp_jump_s`` beyond the time that really
    passed between arrivals (or went back) is ignored, not allowed to age every track out;
    after ``jumps_before_reset`` such frames in a row the stamps are believed and the tracks
    restart (a camera clock that really stepped). Only frames from another host are checked:
    a frame from this host is tracked on its monotonic stamp, which cannot step.

    ``kind``: ``"iou"`` (perception/tracker.py) or ``"kalman"``
    (perception/kalman_tracker.py), which also reads: ``appearance_weight`` (how much a
    colour that disagrees lowers a match's IoU), ``reid_age_s`` (a lost track may be taken
    back this long), ``reid_similarity`` (the least colour likeness to take one back) and
    ``reid_gate`` (how far from its prediction, in box heights).
    """

    high_score: Annotated[float, Range(0, 1)] = 0.4
    low_score: Annotated[float, Range(0, 1)] = 0.15
    iou: Annotated[float, Range(0, 1)] = 0.25
    max_age_s: Annotated[float, Range(0.01, 60)] = 1.0
    max_stamp_jump_s: Annotated[float, Range(0.01, 60)] = 0.5
    jumps_before_reset: Annotated[int, Range(1, 1000)] = 3
    kind: TrackerKind = TrackerKind.KALMAN
    appearance_weight: Annotated[float, Range(0, 1)] = 0.3
    reid_age_s: Annotated[float, Range(0.01, 60)] = 4.0
    reid_similarity: Annotated[float, Range(0, 1)] = 0.8
    reid_gate: Annotated[float, Range(0, 20)] = 1.5

    def __post_init__(self) -> None:
        check_bounds(self, "tracker", TrackerParams)
        enum_field(self, "kind", TrackerKind, "tracker.kind")
        if self.low_score > self.high_score:
            raise ConfigError("tracker.low_score must not be above tracker.high_score")
