"""Drawing detections onto a copy of an image, for humans to check by eye: the detector's
``--save-dir`` and the ROS 2 bridge's debug image."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from common.boxes import Boxes

_FONT = cv2.FONT_HERSHEY_SIMPLEX


def class_colour(class_id: int) -> tuple[int, int, int]:
    """A stable, well-spread BGR colour for a class id (golden-ratio hue steps)."""
    hue = int((class_id * 0.618033988749895 % 1.0) * 180)
    hsv = np.array([[[hue, 200, 255]]], np.uint8)
    b, g, r = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0]
    return int(b), int(g), int(r)


def _value_text(value: bool | int | float) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    return str(value) if isinstance(value, int) else f"{value:.3g}"


def column_labels(columns: Mapping[str, npt.NDArray[Any]], n: int) -> list[str]:
    """Each of ``n`` detections' columns as label text, ``distance_m=2.41 near=yes`` (in the
    columns' order; "" for none): how every human-readable view shows them."""
    if not columns:
        return [""] * n
    per_column = [
        [f"{name}={_value_text(v)}" for v in values.tolist()] for name, values in columns.items()
    ]
    return [" ".join(words) for words in zip(*per_column, strict=True)]


def annotate(
    image_bgr: npt.NDArray[np.uint8], boxes: Boxes, class_names: Sequence[str]
) -> npt.NDArray[np.uint8]:
    """A copy of ``image_bgr`` with each box and a ``name score`` label drawn on it (and
    ``#id`` when the box has a track id, then the box's columns: :func:`column_labels`).

    Line width and font size follow the image size so labels stay legible on large photos.
    """
    out = image_bgr.copy()
    h, w = out.shape[:2]
    thickness = max(1, round(max(h, w) / 400))
    font_scale = max(0.4, max(h, w) / 1500)
    corners = np.rint(boxes.xyxy).astype(np.int32).tolist()
    n = len(corners)
    tracks = boxes.track_ids.tolist() if boxes.track_ids is not None else [-1] * n
    extras = column_labels(boxes.columns, n)
    # One loop per detection is fine here: drawing is not on the detection hot path.
    for (x1, y1, x2, y2), name, score, cid, tid, extra in zip(
        corners, class_names, boxes.scores.tolist(), boxes.class_ids.tolist(), tracks, extras,
        strict=True,
    ):  # fmt: skip
        colour = class_colour(cid)
        cv2.rectangle(out, (x1, y1), (x2, y2), colour, thickness, cv2.LINE_AA)
        text = f"{name} {score:.2f}" + (f" #{tid}" if tid >= 0 else "")
        text += f" {extra}" if extra else ""
        (tw, th), base = cv2.getTextSize(text, _FONT, font_scale, max(1, thickness - 1))
        top = y1 - th - base if y1 - th - base >= 0 else y1  # inside the box at the top edge
        left = max(0, min(x1, w - tw))  # a box at the right edge: the label moves in, whole
        cv2.rectangle(out, (left, top), (left + tw, top + th + base), colour, cv2.FILLED)
        cv2.putText(
            out,
            text,
            (left, top + th),
            _FONT,
            font_scale,
            (0, 0, 0),
            max(1, thickness - 1),
            cv2.LINE_AA,
        )
    return out
