"""Accuracy of detections against labelled boxes, scored by faster-coco-eval.

The scoring is the COCO protocol as the maintained evaluator implements it (never our own
mAP): boxes match at IoU >= 0.50 ... 0.95, greedily by descending score, at most 100 detections
per image and class. We only translate: our detections to COCO result dicts, and the
evaluator's arrays to the figures we report.

* ``map50`` / ``map50_95``: COCO's AP at IoU 0.50, and averaged over IoU 0.50:0.05:0.95,
  over the classes that have at least one labelled box.
* ``precision`` / ``recall`` at ``conf_threshold``: from the evaluator's own matches at IoU 0.50.
  Precision = matched detections / detections scoring at least the threshold; recall = matched
  labels / labels. Summed over classes (micro-averaged); per class as well.

Detections fed to mAP should come from a low confidence floor (0.001): AP integrates over
every score, and a high floor cuts the curve short. The threshold only applies to P and R.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from common.boxes import Boxes
from services.detector.contract import DetectorSettings
from tools.evaluation.labelled import DatasetError

#: Where precision and recall are read by default: the stack's own detector.conf.
DEFAULT_CONF_THRESHOLD = DetectorSettings().conf
MATCH_IOU = 0.5


@dataclass(frozen=True, slots=True)
class ClassAccuracy:
    """One class: AP from the evaluator, and P/R at the threshold with the counts behind them."""

    ap50: float
    ap50_95: float
    precision: float
    recall: float
    labels: int
    detections: int
    true_positives: int


@dataclass(frozen=True, slots=True)
class AccuracyReport:
    map50: float
    map50_95: float
    precision: float
    recall: float
    conf_threshold: float
    per_class: dict[str, ClassAccuracy]
    images: int
    labels: int
    detections: int
    excluded_categories: tuple[str, ...] = ()

    def to_json_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["excluded_categories"] = list(self.excluded_categories)
        return out


def match_categories(
    categories: Mapping[int, str], model_names: Sequence[str]
) -> tuple[dict[str, int], tuple[str, ...]]:
    """Map the model's class names to dataset category ids, by name (case-insensitive).

    Returns (model name -> category id, dataset category names the model does not know).
    """

    def key(name: str) -> str:
        return name.strip().lower()

    by_name = {key(name): cid for cid, name in categories.items()}
    known = {key(name) for name in model_names}
    mapping = {name: by_name[key(name)] for name in model_names if key(name) in by_name}
    excluded = tuple(name for name in categories.values() if key(name) not in known)
    return mapping, excluded


def to_results(
    detections: Mapping[int, Boxes], names: Sequence[str], name_to_category: Mapping[str, int]
) -> list[dict[str, Any]]:
    """COCO result dicts (image_id, category_id, bbox x/y/w/h, score) of ``detections``, the
    boxes of each image by image id (in its pixels), whose class ids index ``names``, the
    model's class names. Classes the dataset does not label are left out, as COCO evaluates
    only the dataset's categories."""
    category = [name_to_category.get(name) for name in names]
    results = []
    for image_id, boxes in detections.items():
        for box, score, class_id in zip(
            boxes.xyxy.tolist(), boxes.scores.tolist(), boxes.class_ids.tolist(), strict=True
        ):
            cid = category[class_id]
            if cid is None:
                continue
            x1, y1, x2, y2 = box
            results.append(
                {
                    "image_id": image_id,
                    "category_id": cid,
                    "bbox": [x1, y1, x2 - x1, y2 - y1],
                    "score": score,
                }
            )
    return results


def _quiet(*_args: Any, **_kwargs: Any) -> None:
    """The evaluator prints its progress and tables; we report our own figures instead."""


def run_cocoeval(ground_truth: dict[str, Any], results: list[dict[str, Any]]) -> Any:
    """Evaluate bbox results with faster-coco-eval's defaults; inputs are not modified.

    Returns the evaluator (``COCOeval_faster``) after evaluate, accumulate and summarize.
    """
    from faster_coco_eval import COCO, COCOeval_faster  # compiled; only `evaluate` needs it

    coco_gt = COCO(ground_truth, use_deepcopy=True, print_function=_quiet)
    coco_dt = coco_gt.loadRes([dict(r) for r in results])
    evaluator = COCOeval_faster(coco_gt, coco_dt, "bbox", print_function=_quiet)
    evaluator.evaluate()
    evaluator.accumulate()
    evaluator.summarize()
    return evaluator


def _ap(precision: npt.NDArray[np.float64]) -> float:
    """Mean of the defined entries (-1 marks "no labels"), as COCO's summarize averages."""
    valid = precision[precision > -1]
    return float(valid.mean()) if valid.size else 0.0


def _ratio(part: int, whole: int) -> float:
    return part / whole if whole else 0.0


def evaluate(
    ground_truth: dict[str, Any],
    results: list[dict[str, Any]],
    conf_threshold: float = DEFAULT_CONF_THRESHOLD,
    excluded_categories: tuple[str, ...] = (),
) -> AccuracyReport:
    """Score COCO ``results`` against COCO ``ground_truth`` (see the module docstring)."""
    gt_anns = ground_truth["annotations"]
    labels = Counter(a["category_id"] for a in gt_anns if not a.get("iscrowd", 0))
    if not labels:
        raise DatasetError("no labelled boxes of any class the model knows; nothing to score")
    ev = run_cocoeval(ground_truth, results)
    if not np.isclose(ev.params.iouThrs[0], MATCH_IOU):
        raise RuntimeError(f"the evaluator's first IoU threshold is not {MATCH_IOU}")
    stats = ev.stats_as_dict
    # precision[iou, recall, class, area range, max dets]: area "all", the largest max dets.
    precision = ev.eval["precision"][:, :, :, 0, -1]
    crowd = {a["id"] for a in gt_anns if a.get("iscrowd", 0)}
    matched_to: dict[int, int] = {}
    for key in ev.eval["matched"]:  # "<detection id>_<label id>", matched at IoU 0.50
        dt_id, gt_id = (int(v) for v in key.split("_", 1))
        matched_to[dt_id] = gt_id
    shown = Counter[int]()
    hits = Counter[int]()
    for dt_id, ann in ev.cocoDt.anns.items():
        if ann["score"] < conf_threshold or matched_to.get(dt_id) in crowd:
            continue  # below the threshold, or on a crowd region: neither right nor wrong
        shown[ann["category_id"]] += 1
        hits[ann["category_id"]] += dt_id in matched_to
    names = {c["id"]: c["name"] for c in ground_truth["categories"]}
    per_class = {}
    for k, cid in enumerate(ev.params.catIds):
        if not labels[cid]:
            continue  # no labels: AP undefined, and COCO leaves the class out of the mean
        per_class[names[cid]] = ClassAccuracy(
            ap50=_ap(precision[0, :, k]),
            ap50_95=_ap(precision[:, :, k]),
            precision=_ratio(hits[cid], shown[cid]),
            recall=_ratio(hits[cid], labels[cid]),
            labels=labels[cid],
            detections=shown[cid],
            true_positives=hits[cid],
        )
    return AccuracyReport(
        map50=max(float(stats["AP_50"]), 0.0),
        map50_95=max(float(stats["AP_all"]), 0.0),
        precision=_ratio(sum(hits.values()), sum(shown.values())),
        recall=_ratio(sum(hits.values()), sum(labels.values())),
        conf_threshold=conf_threshold,
        per_class=per_class,
        images=len(ground_truth["images"]),
        labels=sum(labels.values()),
        detections=sum(shown.values()),
        excluded_categories=excluded_categories,
    )
