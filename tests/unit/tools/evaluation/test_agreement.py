"""Agreement between two backends' detections, scored as COCO mAP with faster-coco-eval."""

from __future__ import annotations

import numpy as np
import pytest
from faster_coco_eval import COCO, COCOeval_faster

from common.boxes import Boxes
from perception.types import DetectionResult
from tools.evaluation.agreement import score

NAMES = ("person", "bicycle", "car")


def result(boxes: list[tuple[float, float, float, float, float, int]]) -> DetectionResult:
    """A 640x480 image's detections from (x1, y1, x2, y2, score, class) rows."""
    rows = np.array(boxes, dtype=np.float64).reshape(-1, 6)
    return DetectionResult(
        boxes=Boxes(
            xyxy=rows[:, :4].astype(np.float32),
            scores=rows[:, 4].astype(np.float32),
            class_ids=rows[:, 5].astype(np.int32),
        ),
        names=NAMES,
        image_width=640,
        image_height=480,
    )


REFERENCE = [
    result(
        [(10, 20, 110, 220, 0.9, 0), (300, 100, 420, 180, 0.8, 2), (500, 300, 600, 460, 0.6, 1)]
    ),
    result([(50, 50, 250, 350, 0.95, 0)]),
    result([]),
    result([(0, 0, 640, 480, 0.7, 2), (100, 100, 140, 150, 0.4, 0)]),
]


def shifted(r: DetectionResult, dx: float) -> DetectionResult:
    return result(
        [
            (*(b + np.array([dx, 0, dx, 0])).tolist(), s, c)
            for b, s, c in zip(r.xyxy, r.scores.tolist(), r.class_ids.tolist(), strict=True)
        ]
    )


def direct_coco(
    reference: list[DetectionResult], candidate: list[DetectionResult]
) -> tuple[float, float]:
    """mAP50 and mAP50-95 computed straight with faster-coco-eval, written out independently."""
    gt: dict[str, list[dict[str, object]]] = {"images": [], "annotations": [], "categories": []}
    dets: list[dict[str, object]] = []
    for i, (ref, cand) in enumerate(zip(reference, candidate, strict=True)):
        gt["images"].append({"id": i + 10, "width": ref.image_width, "height": ref.image_height})
        for (x1, y1, x2, y2), c in zip(ref.xyxy.tolist(), ref.class_ids.tolist(), strict=True):
            gt["annotations"].append(
                {
                    "id": len(gt["annotations"]) + 1,
                    "image_id": i + 10,
                    "category_id": c + 100,
                    "bbox": [x1, y1, x2 - x1, y2 - y1],
                    "area": (x2 - x1) * (y2 - y1),
                    "iscrowd": 0,
                }
            )
        for (x1, y1, x2, y2), s, c in zip(
            cand.xyxy.tolist(), cand.scores.tolist(), cand.class_ids.tolist(), strict=True
        ):
            dets.append(
                {
                    "image_id": i + 10,
                    "category_id": c + 100,
                    "bbox": [x1, y1, x2 - x1, y2 - y1],
                    "score": s,
                }
            )
    used = {int(a["category_id"]) for a in gt["annotations"]}  # type: ignore[call-overload]
    gt["categories"] = [{"id": c} for c in sorted(used)]
    coco_gt = COCO(gt)
    evaluator = COCOeval_faster(coco_gt, coco_gt.loadRes(dets), iouType="bbox")
    evaluator.evaluate()
    evaluator.accumulate()
    evaluator.summarize()
    return float(evaluator.stats[1]), float(evaluator.stats[0])


def test_identical_outputs_agree_perfectly() -> None:
    agreement = score(REFERENCE, REFERENCE)
    assert agreement.map50 == pytest.approx(1.0)
    assert agreement.map50_95 == pytest.approx(1.0)
    assert (agreement.reference_boxes, agreement.candidate_boxes) == (6, 6)


def test_a_dropped_box_lowers_map50() -> None:
    candidate = [*REFERENCE]
    candidate[0] = result([(10, 20, 110, 220, 0.9, 0), (300, 100, 420, 180, 0.8, 2)])
    agreement = score(REFERENCE, candidate)
    assert agreement.map50 < 1.0
    assert agreement.candidate_boxes == 5


def test_small_shifts_cost_map50_95_before_map50_and_big_ones_cost_both() -> None:
    small = score(REFERENCE, [shifted(r, 6.0) for r in REFERENCE])
    assert small.map50 == pytest.approx(1.0)  # still IoU >= 0.5 everywhere
    assert small.map50_95 < 1.0
    big = score(REFERENCE, [shifted(r, 200.0) for r in REFERENCE])
    assert big.map50 < small.map50


def test_a_wrong_class_is_a_miss() -> None:
    candidate = [*REFERENCE]
    candidate[1] = result([(50, 50, 250, 350, 0.95, 1)])
    assert score(REFERENCE, candidate).map50 < 1.0


@pytest.mark.parametrize(
    "candidate",
    [
        REFERENCE,
        [shifted(r, 6.0) for r in REFERENCE],
        [shifted(r, 40.0) for r in REFERENCE],
        [REFERENCE[0], result([]), REFERENCE[2], shifted(REFERENCE[3], 15.0)],
        [result([(12, 18, 108, 225, 0.5, 0), (0, 0, 50, 50, 0.99, 0)]), *REFERENCE[1:]],
    ],
)
def test_numbers_match_calling_faster_coco_eval_directly(candidate: list[DetectionResult]) -> None:
    agreement = score(REFERENCE, candidate)
    assert (agreement.map50, agreement.map50_95) == pytest.approx(direct_coco(REFERENCE, candidate))


def test_a_reference_without_detections_scores_by_whether_the_candidate_agrees() -> None:
    empty = [result([]), result([])]
    assert score(empty, empty).map50 == 1.0
    assert score(empty, [result([(0, 0, 10, 10, 0.9, 0)]), result([])]).map50 == 0.0


def test_different_image_counts_are_refused() -> None:
    with pytest.raises(ValueError, match="4 reference results but 3 candidate ones"):
        score(REFERENCE, REFERENCE[:3])


def test_as_dict_is_json_ready() -> None:
    assert score(REFERENCE, REFERENCE).as_dict() == {
        "map50": 1.0,
        "map50_95": 1.0,
        "reference_boxes": 6,
        "candidate_boxes": 6,
    }
