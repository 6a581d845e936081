"""What a labelled dataset is once read: images, categories and COCO-style boxes, all checked.

Both readers (COCO JSON in :mod:`tools.evaluation.datasets`, the YOLO layout in
:mod:`tools.evaluation.yolo_dataset`) build a :class:`LabelledSet` and raise
:class:`DatasetError`; they share :func:`check_box`.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.errors import ConfigError

#: A box may overhang its image by this many pixels (rounding in labelling tools) and still count.
EDGE_TOLERANCE_PX = 1.0


class DatasetError(ConfigError):
    """A labelled dataset that cannot be evaluated; the message names the file and the problem.

    A ConfigError, so command-line entry points print it as one line and exit 2.
    """


@dataclass(frozen=True, slots=True)
class LabelledImage:
    """One image of a dataset: its id in the annotations, its file and its size in pixels."""

    id: int
    path: Path
    width: int
    height: int


@dataclass(frozen=True, slots=True)
class LabelledSet:
    """A checked dataset. ``annotations`` are COCO dicts: id, image_id, category_id, bbox
    (x, y, w, h in pixels), area and iscrowd."""

    source: Path
    images: tuple[LabelledImage, ...]
    categories: dict[int, str]
    annotations: tuple[dict[str, Any], ...]

    def ground_truth(self, category_ids: Collection[int]) -> dict[str, Any]:
        """COCO ground truth restricted to ``category_ids`` (the classes the model knows)."""
        keep = set(category_ids)
        return {
            "images": [
                {"id": im.id, "file_name": str(im.path), "width": im.width, "height": im.height}
                for im in self.images
            ],
            "categories": [
                {"id": cid, "name": name} for cid, name in self.categories.items() if cid in keep
            ],
            "annotations": [dict(a) for a in self.annotations if a["category_id"] in keep],
        }


def check_box(where: str, box: tuple[float, float, float, float], width: int, height: int) -> None:
    """Raise DatasetError unless ``box`` (x, y, w, h pixels) is finite, non-empty and inside."""
    x, y, w, h = box
    if not all(math.isfinite(v) for v in box):
        raise DatasetError(f"{where}: box {list(box)} is not finite")
    if w <= 0 or h <= 0:
        raise DatasetError(f"{where}: box {list(box)} has no area (width and height must be > 0)")
    tol = EDGE_TOLERANCE_PX
    if x < -tol or y < -tol or x + w > width + tol or y + h > height + tol:
        raise DatasetError(
            f"{where}: box [x={x:g}, y={y:g}, w={w:g}, h={h:g}] lies outside its "
            f"{width}x{height} image"
        )


def read_text(path: Path) -> str:
    """A dataset file's text (UTF-8); DatasetError naming it when it cannot be read."""
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{path}: cannot read ({exc})") from exc
