"""Post-processing of decoded candidates (Boxes): class filter, class-aware NMS, top-k.

NMS runs in OpenCV (``cv2.dnn.NMSBoxesBatched``), which keeps boxes of different classes apart
by offsetting each class into its own coordinate range. Measured on a 2-core EPYC against a
vectorised numpy loop, it was 15-20x faster (0.06 ms vs 1.3 ms for 30 boxes, 0.8 ms vs 12 ms for
300) and gave identical indices.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import cv2
import numpy as np
import numpy.typing as npt

from common.boxes import Boxes
from common.errors import ConfigError

#: Candidates kept (highest scores first) before NMS, bounding its O(n^2) cost at low ``conf``.
MAX_NMS_CANDIDATES = 30_000


def class_mask(names: Sequence[str], wanted: Sequence[str] | None) -> npt.NDArray[np.bool_] | None:
    """A ``(len(names),)`` mask of the classes in ``wanted``; ``None`` when all are wanted.

    Raises ConfigError, listing the valid names on one line, when a name is unknown.
    """
    if wanted is None:
        return None
    index = {name: i for i, name in enumerate(names)}
    unknown = [name for name in wanted if name not in index]
    if unknown:
        raise ConfigError(
            f"unknown class name(s) {', '.join(map(repr, unknown))}; "
            f"valid names: {', '.join(names)}"
        )
    mask = np.zeros(len(names), np.bool_)
    mask[[index[name] for name in wanted]] = True
    return mask


def nms(
    xyxy: npt.NDArray[np.float32],
    scores: npt.NDArray[np.float32],
    class_ids: npt.NDArray[np.int32],
    iou: float,
) -> npt.NDArray[np.intp]:
    """Greedy class-aware NMS; returns the kept indices by descending score.

    A box is suppressed when its IoU with a higher-scored kept box of the same class is above
    ``iou``. Boxes are xyxy in any one pixel frame; scores must be positive.
    """
    if xyxy.shape[0] == 0:
        return np.zeros(0, np.intp)
    xywh = np.empty(xyxy.shape, np.float64)
    xywh[:, :2] = xyxy[:, :2]
    xywh[:, 2:] = xyxy[:, 2:] - xyxy[:, :2]
    # OpenCV's stubs ask for sequences; arrays are what it actually reads fastest.
    kept = cv2.dnn.NMSBoxesBatched(
        cast(Any, xywh), cast(Any, scores), cast(Any, class_ids), 0.0, iou
    )
    return np.asarray(kept, dtype=np.intp).reshape(-1)


def select(candidates: Boxes, *, iou: float, max_det: int, apply_nms: bool) -> Boxes:
    """Keep the best ``max_det`` candidates, after class-aware NMS when ``apply_nms``.

    End-to-end models already ran NMS in the graph, so they pass ``apply_nms=False``.
    The result is sorted by descending score. Candidates are Boxes, so every row is finite
    and upright (the decoder dropped the rest), as OpenCV's NMS needs.
    """
    n = len(candidates)
    if n == 0:
        return candidates
    order = np.argsort(-candidates.scores, kind="stable")
    if apply_nms:
        if n > MAX_NMS_CANDIDATES:
            candidates = candidates.take(order[:MAX_NMS_CANDIDATES])
        order = nms(candidates.xyxy, candidates.scores, candidates.class_ids, iou)
    return candidates.take(order[:max_det])
