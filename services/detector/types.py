"""Value types of the detector: its settings and what one detection call returns.

Arrays follow supervision's struct-of-arrays layout: row ``i`` of ``xyxy``, ``scores`` and
``class_ids`` describes detection ``i``. Boxes are in the pixels of the original image (before
letterboxing), ``x1, y1, x2, y2`` with the origin at the top-left corner.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from common.errors import ConfigError

#: Defaults, named so that no threshold is a magic number elsewhere.
DEFAULT_CONF = 0.25
DEFAULT_IOU = 0.45
DEFAULT_MAX_DET = 300


@dataclass(frozen=True, slots=True, kw_only=True)
class StageTiming:
    """Wall-clock milliseconds spent in each stage of one detection call."""

    preprocess_ms: float = 0.0
    inference_ms: float = 0.0
    postprocess_ms: float = 0.0

    @property
    def total_ms(self) -> float:
        """Sum of the three stages, in milliseconds."""
        return self.preprocess_ms + self.inference_ms + self.postprocess_ms


def _empty_xyxy() -> npt.NDArray[np.float32]:
    return np.zeros((0, 4), np.float32)


def _empty_scores() -> npt.NDArray[np.float32]:
    return np.zeros(0, np.float32)


def _empty_class_ids() -> npt.NDArray[np.int32]:
    return np.zeros(0, np.int32)


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectionResult:
    """The detections of one image, sorted by descending score.

    ``xyxy`` is ``(n, 4)`` float32 in original-image pixels, clipped to the image; ``scores`` is
    ``(n,)`` float32 in 0..1; ``class_ids`` is ``(n,)`` int32 indexing ``names`` (all the model's
    class names, not only those detected).
    """

    xyxy: npt.NDArray[np.float32] = field(default_factory=_empty_xyxy)
    scores: npt.NDArray[np.float32] = field(default_factory=_empty_scores)
    class_ids: npt.NDArray[np.int32] = field(default_factory=_empty_class_ids)
    names: tuple[str, ...] = ()
    image_width: int = 0
    image_height: int = 0
    timing: StageTiming = field(default_factory=StageTiming)

    def __post_init__(self) -> None:
        if self.xyxy.ndim != 2 or self.xyxy.shape[1] != 4 or self.xyxy.dtype != np.float32:
            raise ValueError(
                f"xyxy must be an (n, 4) float32 array, got shape {self.xyxy.shape} "
                f"dtype {self.xyxy.dtype}"
            )
        n = self.xyxy.shape[0]
        if self.scores.shape != (n,) or self.scores.dtype != np.float32:
            raise ValueError(
                f"scores must be a ({n},) float32 array to match xyxy, got shape "
                f"{self.scores.shape} dtype {self.scores.dtype}"
            )
        if self.class_ids.shape != (n,) or self.class_ids.dtype != np.int32:
            raise ValueError(
                f"class_ids must be a ({n},) int32 array to match xyxy, got shape "
                f"{self.class_ids.shape} dtype {self.class_ids.dtype}"
            )
        if (
            n
            and self.names
            and (self.class_ids.min() < 0 or self.class_ids.max() >= len(self.names))
        ):
            raise ValueError(
                f"class_ids must lie in 0..{len(self.names) - 1} (one per name), got "
                f"{self.class_ids.min()}..{self.class_ids.max()}"
            )

    def __len__(self) -> int:
        return int(self.xyxy.shape[0])

    @property
    def class_names(self) -> list[str]:
        """The class name of each detection, in row order."""
        if not self.names:
            return [f"class_{i}" for i in self.class_ids.tolist()]
        return [self.names[i] for i in self.class_ids.tolist()]


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectorParams:
    """Post-processing settings, validated on construction.

    ``conf`` is the minimum score kept (score = objectness x class score for YOLOv5-style
    models); ``iou`` is the overlap above which a lower-scored box of the same class is
    suppressed; ``max_det`` caps detections per image; ``classes`` keeps only those class names
    (``None`` keeps all).
    """

    conf: float = DEFAULT_CONF
    iou: float = DEFAULT_IOU
    max_det: int = DEFAULT_MAX_DET
    classes: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        for name, value in (("conf", self.conf), ("iou", self.iou)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and 0 <= value <= 1):
                raise ConfigError(f"{name} must be a number in [0, 1], got {value!r}")
        if isinstance(self.max_det, bool) or not isinstance(self.max_det, int) or self.max_det < 1:
            raise ConfigError(f"max_det must be a positive integer, got {self.max_det!r}")
        if self.classes is not None:
            if not isinstance(self.classes, tuple) or not all(
                isinstance(c, str) and c for c in self.classes
            ):
                raise ConfigError(
                    f"classes must be a tuple of non-empty class names, got {self.classes!r}"
                )
            if not self.classes:
                raise ConfigError("classes must name at least one class (use None to keep all)")
