"""Accuracy on the project's hand-labelled photos: AP50 of a detector, and box agreement.

The labelled set is ``tools/evaluation/data/skimage_coco.json`` (package data): hand-drawn COCO
boxes on the
scikit-image sample photos, which ship offline with scikit-image. The photos are written to a
temporary folder for the dataset reader (it checks every file and size) and scored with the
metrics service's COCO evaluation, at the low score floor mAP needs.
"""

from __future__ import annotations

import dataclasses
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from common.errors import ConfigError
from common.images import load_sample
from perception import DetectionResult, Detector
from tools.evaluation.data.write_images import ANNOTATIONS as LABELLED_SET
from tools.evaluation.data.write_images import write_images

EVAL_CONF = 0.001  # the score floor of detections fed to mAP (COCO practice)
MATCH_IOU = 0.5


def labelled_ap50(det: Detector) -> float:
    """COCO AP50 of ``det`` on the labelled photos."""
    from tools.evaluation.datasets import load_dataset
    from tools.evaluation.evaluate import score

    if not LABELLED_SET.is_file():
        raise ConfigError(f"the labelled set {LABELLED_SET} is missing (it ships with the package)")
    saved = det.settings
    det.settings = dataclasses.replace(saved, conf=EVAL_CONF)
    try:
        with tempfile.TemporaryDirectory(prefix="labelled-") as tmp:
            dataset = load_dataset(LABELLED_SET, _written(Path(tmp)))
            found = {
                item.id: det.detect(load_sample(item.path.stem)).boxes for item in dataset.images
            }
    finally:
        det.settings = saved
    return float(score(dataset, det.names, found).map50)


def _written(folder: Path) -> Path:
    """``folder``, with every labelled photo written into it."""
    write_images(folder)
    return folder


def _iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of each box in ``a`` (n, 4) with each in ``b`` (m, 4), xyxy."""
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.clip(rb - lt, 0, None).prod(axis=2)
    area_a = (a[:, 2:] - a[:, :2]).prod(axis=1)
    area_b = (b[:, 2:] - b[:, :2]).prod(axis=1)
    return np.asarray(inter / np.maximum(area_a[:, None] + area_b[None, :] - inter, 1e-9))


def matched_boxes(
    reference: Sequence[DetectionResult], candidate: Sequence[DetectionResult]
) -> tuple[int, int]:
    """``(matched, total)``: reference boxes that a candidate box of the same class overlaps
    at IoU >= 0.5, each candidate box used once (greedy, best overlap first)."""
    matched = total = 0
    for ref, cand in zip(reference, candidate, strict=True):
        total += len(ref)
        if not len(ref) or not len(cand):
            continue
        ious = _iou(ref.xyxy.astype(np.float64), cand.xyxy.astype(np.float64))
        ious[ref.class_ids[:, None] != cand.class_ids[None, :]] = 0.0
        used: set[int] = set()
        for i in np.argsort(-ious.max(axis=1)):
            for j in np.argsort(-ious[i]):
                if ious[i, j] < MATCH_IOU:
                    break
                if int(j) not in used:
                    used.add(int(j))
                    matched += 1
                    break
    return matched, total
