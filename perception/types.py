"""What one detection call returns: the detections, and what they refer to.

The detections themselves are a :class:`common.boxes.Boxes` (the one struct of arrays, checked
there); a DetectionResult adds the model's class names, the image size and the stage timing.
Boxes are in the pixels of the original image (before letterboxing), ``x1, y1, x2, y2`` with
the origin at the top-left corner. The post-processing settings are
``perception.settings.DecodeOptions``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from common.boxes import Boxes


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


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectionResult:
    """The detections of one image, sorted by descending score.

    ``boxes`` is in original-image pixels, clipped to the image, with scores in 0..1 and
    class ids indexing ``names`` (all the model's class names, not only those detected);
    ``xyxy``, ``scores`` and ``class_ids`` read its arrays.
    """

    boxes: Boxes = field(default_factory=Boxes)
    names: tuple[str, ...] = ()
    image_width: int = 0
    image_height: int = 0
    timing: StageTiming = field(default_factory=StageTiming)
    #: False when the model's output for this image held a NaN, an infinity or an absurd
    #: magnitude (perception/decode.py): ``boxes`` is then empty, not a verdict.
    output_sane: bool = True

    def __post_init__(self) -> None:
        ids = self.boxes.class_ids
        if len(ids) and self.names and (ids.min() < 0 or ids.max() >= len(self.names)):
            raise ValueError(
                f"class_ids must lie in 0..{len(self.names) - 1} (one per name), got "
                f"{ids.min()}..{ids.max()}"
            )

    def __len__(self) -> int:
        return len(self.boxes)

    @property
    def xyxy(self) -> npt.NDArray[np.float32]:
        return self.boxes.xyxy

    @property
    def scores(self) -> npt.NDArray[np.float32]:
        return self.boxes.scores

    @property
    def class_ids(self) -> npt.NDArray[np.int32]:
        return self.boxes.class_ids

    @property
    def class_names(self) -> list[str]:
        """The class name of each detection, in row order."""
        if not self.names:
            return [f"class_{i}" for i in self.class_ids.tolist()]
        return [self.names[i] for i in self.class_ids.tolist()]
