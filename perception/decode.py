"""The YOLO output families: telling them apart, and decoding each into candidate boxes.

Three layouts cover the common YOLO exports (``B`` batch, ``C`` classes):

* ``yolov5``  ``[B, N, 5 + C]`` rows of cx, cy, w, h, objectness, C class scores;
  score = objectness x class score. N = 3 anchors x grid cells (25200 at 640).
* ``yolov8``  ``[B, 4 + C, N]`` channels-first cx, cy, w, h, C class scores, no objectness
  (Ultralytics YOLOv8 / YOLO11 ONNX export). N = grid cells (8400 at 640).
* ``end2end`` ``[B, K, 6]`` rows of x1, y1, x2, y2, score, class: NMS already done in the graph
  (YOLOv10, YOLO26).

They are told apart by the output shape, checked against the class count from the ``names``
metadata when the model has one, never by file name. Scores are expected already sigmoided, as
every Ultralytics export does. Each image's candidates are a :class:`common.boxes.Boxes`, xyxy
in network-input pixels; rows that are not boxes (a non-finite value, x2 < x1) are dropped here.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.boxes import Boxes, valid_rows
from common.errors import UnknownModelFamily

#: The strides of the three YOLO detection heads, in input pixels.
HEAD_STRIDES = (8, 16, 32)
#: Anchors per grid cell in YOLOv5-style heads.
V5_ANCHORS_PER_CELL = 3
#: Columns of an end-to-end output row: x1, y1, x2, y2, score, class.
END2END_COLUMNS = 6

#: A raw output value beyond this (in either sign) is neither a pixel nor a score: the model
#: is broken (overflowed weights, a bad conversion), and its frame's output is not decoded.
MAX_OUTPUT_MAGNITUDE = 1e6

Dim = int | None  # None: a dynamic dimension


def sane_outputs(output: npt.NDArray[np.floating]) -> npt.NDArray[np.bool_]:
    """Per image of a batch output ``[B, ...]``: True where every value is finite and within
    :data:`MAX_OUTPUT_MAGNITUDE`. One pass: the max of the magnitudes is NaN if any is."""
    peak = np.abs(output.reshape(len(output), -1)).max(axis=1, initial=0.0)
    return np.asarray(peak <= MAX_OUTPUT_MAGNITUDE)


class Family(enum.Enum):
    """A YOLO output layout."""

    YOLOV5 = "yolov5"
    YOLOV8 = "yolov8"
    END2END = "end2end"


@dataclass(frozen=True, slots=True)
class OutputLayout:
    """A family, and its class count when the output shape says it (end-to-end does not)."""

    family: Family
    num_classes: int | None


def v5_anchor_count(input_height: int, input_width: int) -> int:
    """Rows a YOLOv5-style head emits for this input size (25200 at 640x640)."""
    cells = sum(-(-input_height // s) * -(-input_width // s) for s in HEAD_STRIDES)
    return V5_ANCHORS_PER_CELL * cells


def _shape_text(shape: Sequence[Dim]) -> str:
    return "[" + ", ".join("?" if d is None else str(d) for d in shape) + "]"


def detect_family(
    output_shape: Sequence[Dim],
    *,
    num_names: int | None = None,
    input_hw: tuple[int, int] | None = None,
    end2end: bool | None = None,
) -> OutputLayout:
    """Tell the family from the first output's shape (``None`` for dynamic dimensions).

    ``num_names`` (classes in the metadata) rules out layouts whose class count disagrees;
    ``end2end`` is the model's own end2end metadata flag, when it has one. The only shape two
    families share is ``[B, N, 6]`` (a one-class YOLOv5, or an end-to-end head); it is YOLOv5
    when N is the YOLOv5 anchor count for ``input_hw``, else end-to-end.
    Raises UnknownModelFamily with the shape when nothing matches.
    """
    if len(output_shape) != 3:
        raise UnknownModelFamily(
            f"output shape {_shape_text(output_shape)} matches no YOLO family "
            "(expected [B, N, 5+C], [B, 4+C, N] or [B, K, 6])"
        )
    rows, cols = output_shape[1], output_shape[2]
    options: list[OutputLayout] = []
    if cols == END2END_COLUMNS and end2end is not False:
        options.append(OutputLayout(Family.END2END, None))
    if cols is not None and cols > 5 and (rows is None or rows > cols) and end2end is not True:
        options.append(OutputLayout(Family.YOLOV5, cols - 5))
    if rows is not None and rows > 4 and (cols is None or cols > rows) and end2end is not True:
        options.append(OutputLayout(Family.YOLOV8, rows - 4))
    if num_names is not None:
        options = [o for o in options if o.num_classes in (None, num_names)]
    if not options:
        names_text = f" with {num_names} class names" if num_names is not None else ""
        raise UnknownModelFamily(
            f"output shape {_shape_text(output_shape)}{names_text} matches no YOLO family "
            "(expected [B, N, 5+C], [B, 4+C, N] or [B, K, 6])"
        )
    if len(options) > 1:  # [B, N, 6]: one-class YOLOv5 or end-to-end
        is_v5 = input_hw is not None and rows == v5_anchor_count(*input_hw)
        wanted = Family.YOLOV5 if is_v5 else Family.END2END
        options = [o for o in options if o.family is wanted]
    return options[0]


def _allowed_ids(class_mask: npt.NDArray[np.bool_] | None) -> npt.NDArray[np.intp] | None:
    return None if class_mask is None else np.flatnonzero(class_mask)


def _candidates(
    xyxy: npt.NDArray[np.float32],
    scores: npt.NDArray[np.float32],
    class_ids: npt.NDArray[np.int32],
) -> Boxes:
    """The decoded rows that are boxes, the rest dropped.

    A model can emit rows that are not (an fp16 overflow on a GPU, say). Left in, one NaN
    coordinate would poison OpenCV's per-class offsets, and NMS then keeps nothing else.
    """
    ok = valid_rows(xyxy, scores)
    if not ok.all():
        xyxy, scores, class_ids = xyxy[ok], scores[ok], class_ids[ok]
    return Boxes(xyxy=xyxy, scores=scores, class_ids=class_ids)


def _cxcywh_to_xyxy(cxcywh: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    half = cxcywh[:, 2:4] * np.float32(0.5)
    return np.concatenate((cxcywh[:, :2] - half, cxcywh[:, :2] + half), axis=1, dtype=np.float32)


def decode_yolov5(
    output: npt.NDArray[np.float32],
    conf: float,
    class_mask: npt.NDArray[np.bool_] | None = None,
) -> list[Boxes]:
    """Decode ``[B, N, 5 + C]``: best class per row, score = objectness x class score.

    Rows are first filtered on objectness alone, which is cheap and exact: a class score is at
    most 1, so objectness <= conf implies score <= conf. ``class_mask`` (``(C,)`` bool) keeps
    only the allowed classes before the best class is chosen.
    """
    allowed = _allowed_ids(class_mask)
    results = []
    for pred in output:
        rows = pred[np.flatnonzero(pred[:, 4] > conf)]
        cls = rows[:, 5:] if allowed is None else rows[:, 5 + allowed]
        if cls.shape[0] == 0 or cls.shape[1] == 0:
            results.append(Boxes())
            continue
        best = cls.argmax(axis=1)
        scores = cls[np.arange(cls.shape[0]), best] * rows[:, 4]
        keep = scores > conf
        ids = best[keep] if allowed is None else allowed[best[keep]]
        results.append(
            _candidates(
                _cxcywh_to_xyxy(rows[keep, :4]),
                scores[keep].astype(np.float32, copy=False),
                ids.astype(np.int32),
            )
        )
    return results


def decode_yolov8(
    output: npt.NDArray[np.float32],
    conf: float,
    class_mask: npt.NDArray[np.bool_] | None = None,
) -> list[Boxes]:
    """Decode ``[B, 4 + C, N]``: best class per column, score = class score (no objectness)."""
    allowed = _allowed_ids(class_mask)
    results = []
    for pred in output:
        cls = pred[4:] if allowed is None else pred[4 + allowed]
        if cls.shape[0] == 0 or cls.shape[1] == 0:
            results.append(Boxes())
            continue
        cols = np.flatnonzero(cls.max(axis=0) > conf)
        cls = cls[:, cols]
        best = cls.argmax(axis=0)
        scores = cls[best, np.arange(cols.size)]
        ids = best if allowed is None else allowed[best]
        results.append(
            _candidates(
                _cxcywh_to_xyxy(np.ascontiguousarray(pred[:4, cols].T)),
                scores.astype(np.float32, copy=False),
                ids.astype(np.int32),
            )
        )
    return results


def decode_end2end(
    output: npt.NDArray[np.float32],
    conf: float,
    num_classes: int,
    class_mask: npt.NDArray[np.bool_] | None = None,
) -> list[Boxes]:
    """Decode ``[B, K, 6]`` rows of x1, y1, x2, y2, score, class (already NMS-free).

    Rows whose class id falls outside ``0..num_classes-1`` (padding rows) are dropped.
    """
    results = []
    for pred in output:
        ids = pred[:, 5].astype(np.int32)
        keep = (pred[:, 4] > conf) & (ids >= 0) & (ids < num_classes)
        if class_mask is not None:
            keep[keep] &= class_mask[ids[keep]]
        results.append(
            _candidates(
                np.ascontiguousarray(pred[keep, :4], dtype=np.float32),
                pred[keep, 4].astype(np.float32),
                ids[keep],
            )
        )
    return results


def decode(
    layout: OutputLayout,
    output: npt.NDArray[np.float32],
    conf: float,
    num_classes: int,
    class_mask: npt.NDArray[np.bool_] | None = None,
) -> list[Boxes]:
    """Decode ``output`` with the decoder of ``layout.family``; one Boxes per image."""
    if layout.family is Family.YOLOV5:
        return decode_yolov5(output, conf, class_mask)
    if layout.family is Family.YOLOV8:
        return decode_yolov8(output, conf, class_mask)
    return decode_end2end(output, conf, num_classes, class_mask)
