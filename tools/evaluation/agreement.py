"""How far one backend's detections agree with a reference backend's, as COCO mAP.

A faster backend is only worth having if it finds the same objects. With no labelled data set
at hand, the FP32 ONNX Runtime output is taken as ground truth, and each other backend's output
on the same images is scored against it with the COCO protocol (faster-coco-eval, a maintained
C++ reimplementation of pycocotools): mAP50 (boxes matched at IoU >= 0.5) and mAP50-95 (the
mean over IoU 0.50:0.05:0.95, which also punishes small box shifts).

COCO semantics apply: a class the reference never detected has no ground truth and is left out
of the mean, so a candidate's boxes of such a class cost nothing; a candidate's missed or
shifted boxes of a reference class lower the score. When the reference found nothing at all,
the score is 1.0 if the candidate found nothing too, else 0.0 (COCO would answer -1).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from faster_coco_eval import COCO, COCOeval_faster

from perception import DetectionResult


@dataclass(frozen=True, slots=True)
class Agreement:
    """mAP of a candidate against a reference, and how many boxes each had."""

    map50: float
    map50_95: float
    reference_boxes: int
    candidate_boxes: int

    def as_dict(self) -> dict[str, float | int]:
        """JSON-ready, mAPs rounded to 4 places."""
        return {
            "map50": round(self.map50, 4),
            "map50_95": round(self.map50_95, 4),
            "reference_boxes": self.reference_boxes,
            "candidate_boxes": self.candidate_boxes,
        }


def _xywh(box: Sequence[float]) -> list[float]:
    x1, y1, x2, y2 = box
    return [x1, y1, x2 - x1, y2 - y1]


def coco_ground_truth(reference: Sequence[DetectionResult]) -> dict[str, Any]:
    """The reference detections as a COCO ground-truth dict (image ids 1.., class id + 1)."""
    images: list[dict[str, Any]] = []
    annotations: list[dict[str, Any]] = []
    classes: set[int] = set()
    for image_id, result in enumerate(reference, start=1):
        images.append({"id": image_id, "width": result.image_width, "height": result.image_height})
        for box, cid in zip(result.xyxy.tolist(), result.class_ids.tolist(), strict=True):
            xywh = _xywh(box)
            annotations.append(
                {
                    "id": len(annotations) + 1,
                    "image_id": image_id,
                    "category_id": cid + 1,
                    "bbox": xywh,
                    "area": xywh[2] * xywh[3],
                    "iscrowd": 0,
                }
            )
            classes.add(cid + 1)
    return {
        "images": images,
        "annotations": annotations,
        "categories": [{"id": c, "name": str(c)} for c in sorted(classes)],
    }


def coco_detections(candidate: Sequence[DetectionResult]) -> list[dict[str, Any]]:
    """The candidate detections as a COCO results list, with their scores."""
    return [
        {"image_id": image_id, "category_id": cid + 1, "bbox": _xywh(box), "score": score}
        for image_id, result in enumerate(candidate, start=1)
        for box, cid, score in zip(
            result.xyxy.tolist(), result.class_ids.tolist(), result.scores.tolist(), strict=True
        )
    ]


def _quiet(*_args: object, **_kwargs: object) -> None:
    """faster-coco-eval prints progress and a summary table; a benchmark wants neither."""


def score(reference: Sequence[DetectionResult], candidate: Sequence[DetectionResult]) -> Agreement:
    """Score ``candidate`` against ``reference`` (same images, same order) with COCO mAP."""
    if len(reference) != len(candidate):
        raise ValueError(f"{len(reference)} reference results but {len(candidate)} candidate ones")
    n_ref = sum(len(r) for r in reference)
    n_cand = sum(len(c) for c in candidate)
    if n_ref == 0:
        same = 1.0 if n_cand == 0 else 0.0
        return Agreement(same, same, n_ref, n_cand)
    gt = COCO(coco_ground_truth(reference), print_function=_quiet)
    dt = gt.loadRes(coco_detections(candidate))
    evaluator = COCOeval_faster(gt, dt, iouType="bbox", print_function=_quiet)
    evaluator.evaluate()
    evaluator.accumulate()
    evaluator.summarize()
    # stats[0] is AP@[.50:.95], stats[1] AP@.50, both over all areas and 100 detections.
    return Agreement(float(evaluator.stats[1]), float(evaluator.stats[0]), n_ref, n_cand)
