"""Labels drawn on annotated images stay whole inside the image."""

from __future__ import annotations

import numpy as np

from common.annotate import annotate, class_colour
from common.boxes import Boxes


def _label_columns(image: np.ndarray, colour: tuple[int, int, int], rows: slice) -> np.ndarray:
    """Columns where the label's filled background (the class colour) shows in ``rows``."""
    hit = np.all(image[rows] == np.array(colour, np.uint8), axis=-1)
    return np.flatnonzero(hit.any(axis=0))


def test_a_label_at_the_right_edge_moves_in_whole() -> None:
    image = np.full((200, 300, 3), 255, np.uint8)
    boxes = Boxes(
        xyxy=np.array([[270, 60, 299, 150]], np.float32),  # a person cut by the right edge
        scores=np.array([0.91], np.float32),
        class_ids=np.array([0], np.int32),
    )
    out = annotate(image, boxes, ["person"])
    columns = _label_columns(out, class_colour(0), slice(30, 60))  # the label sits above y=60
    # "person 0.91" (about 63 px at this size) is wider than the 30 px between the box and the
    # edge: it starts left of the box and ends at the image's last column, whole, where it
    # used to start at the box and be cut to "perso".
    width = columns.max() - columns.min() + 1
    assert columns.min() < 270 and columns.max() == 299 and width >= 60, (columns.min(), width)
