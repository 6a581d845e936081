"""Scoring against labelled boxes: our translation to and from faster-coco-eval."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from faster_coco_eval import COCO, COCOeval_faster

from common.boxes import Boxes
from tools.evaluation.accuracy import (
    evaluate,
    match_categories,
    to_results,
)
from tools.evaluation.labelled import DatasetError

NAMES = {1: "person", 2: "cat", 5: "cup"}


def _gt(boxes: list[tuple[int, int, list[float]]], crowd: frozenset[int] = frozenset()) -> Any:
    """Ground truth from (image id, category id, xywh) triples."""
    return {
        "images": [{"id": i, "file_name": f"{i}.png", "width": 200, "height": 100} for i in (1, 2)],
        "categories": [{"id": k, "name": v} for k, v in NAMES.items()],
        "annotations": [
            {
                "id": n,
                "image_id": im,
                "category_id": c,
                "bbox": b,
                "area": b[2] * b[3],
                "iscrowd": int(n in crowd),
            }
            for n, (im, c, b) in enumerate(boxes, 1)
        ],
    }


#: The model's class names, which the class ids index; the evaluator matches them by name.
MODEL_NAMES = ("person", "cat", "cup", "dog")


def _dets(rows: list[tuple[str, float, list[float]]]) -> Boxes:
    """One image's detections from (name, score, xyxy) rows."""
    return Boxes(
        xyxy=np.array([r[2] for r in rows], np.float32).reshape(-1, 4),
        scores=np.array([r[1] for r in rows], np.float32),
        class_ids=np.array([MODEL_NAMES.index(r[0]) for r in rows], np.int32),
    )


MAP = {"person": 1, "cat": 2, "cup": 5}


def _silent(*_args: object) -> None:
    """The evaluator prints tables; the test compares numbers."""


def test_perfect_detections_score_one() -> None:
    gt = _gt([(1, 1, [10, 10, 50, 80]), (2, 2, [100, 20, 60, 40])])
    dets = {
        1: _dets([("person", 0.9, [10, 10, 60, 90])]),
        2: _dets([("cat", 0.8, [100, 20, 160, 60])]),
    }
    report = evaluate(gt, to_results(dets, MODEL_NAMES, MAP))
    assert report.map50 == pytest.approx(1.0) and report.map50_95 == pytest.approx(1.0)
    assert report.precision == 1.0 and report.recall == 1.0
    assert set(report.per_class) == {"person", "cat"}  # cup has no labels: no AP, not averaged


def test_precision_and_recall_are_read_at_the_threshold() -> None:
    gt = _gt([(1, 1, [10, 10, 50, 80]), (2, 1, [100, 10, 50, 80])])
    dets = {
        1: _dets([("person", 0.9, [10, 10, 60, 90]), ("person", 0.8, [150, 0, 199, 99])]),
        2: _dets([("person", 0.1, [100, 10, 150, 90]), ("cup", 0.7, [0, 0, 20, 20])]),
    }
    report = evaluate(gt, to_results(dets, MODEL_NAMES, MAP), conf_threshold=0.25)
    person = report.per_class["person"]
    assert (person.detections, person.true_positives, person.labels) == (2, 1, 2)
    assert person.precision == 0.5 and person.recall == 0.5
    # The cup detection is wrong too (cup is evaluated, just unlabelled here): 1 of 3 right.
    assert report.precision == pytest.approx(1 / 3) and report.recall == 0.5
    # AP integrates over all scores: the 0.1 detection still finds the second person.
    assert 0.5 < person.ap50 < 1.0


def test_a_detection_on_a_crowd_region_is_neither_right_nor_wrong() -> None:
    gt = _gt([(1, 1, [10, 10, 50, 80]), (2, 1, [100, 10, 80, 80])], crowd=frozenset({2}))
    dets = {
        1: _dets([("person", 0.9, [10, 10, 60, 90])]),
        2: _dets([("person", 0.9, [110, 20, 150, 60])]),
    }
    report = evaluate(gt, to_results(dets, MODEL_NAMES, MAP))
    assert report.precision == 1.0 and report.recall == 1.0 and report.labels == 1


def test_agrees_with_the_evaluator_called_directly() -> None:
    rng = np.random.default_rng(3)
    labels: list[tuple[int, int, list[float]]] = []
    rows: dict[int, list[tuple[str, float, list[float]]]] = {1: [], 2: []}
    for image in (1, 2):
        for cid, name in ((1, "person"), (2, "cat"), (5, "cup")):
            x, y = rng.uniform(0, 100), rng.uniform(0, 50)
            labels.append((image, cid, [x, y, 40.0, 30.0]))
            for _ in range(4):  # near misses, good hits and junk at random scores
                dx, dy = rng.normal(0, 6, 2)
                box = [x + dx, y + dy, min(x + dx + 40, 200), min(y + dy + 30, 100)]
                rows[image].append((name, float(rng.uniform(0.01, 1)), box))
    gt = _gt(labels)
    dets = {i: _dets(r) for i, r in rows.items()}
    report = evaluate(gt, to_results(dets, MODEL_NAMES, MAP))

    coco_gt = COCO(gt)
    results = []
    for image_id, b in dets.items():
        for class_id, score, (x1, y1, x2, y2) in zip(b.class_ids, b.scores, b.xyxy, strict=True):
            xywh = [float(x1), float(y1), float(x2 - x1), float(y2 - y1)]
            cid = MAP[MODEL_NAMES[class_id]]
            results.append(
                {"image_id": image_id, "category_id": cid, "bbox": xywh, "score": float(score)}
            )
    direct = COCOeval_faster(coco_gt, coco_gt.loadRes(results), "bbox", print_function=_silent)
    direct.evaluate()
    direct.accumulate()
    direct.summarize()
    assert report.map50_95 == direct.stats[0] and report.map50 == direct.stats[1]
    precision = direct.eval["precision"]
    for k, cid in enumerate(direct.params.catIds):
        p = precision[:, :, k, 0, -1]
        assert report.per_class[NAMES[cid]].ap50_95 == np.mean(p[p > -1])
        assert report.per_class[NAMES[cid]].ap50 == np.mean(p[0][p[0] > -1])


def test_categories_map_by_name_and_unknown_ones_are_reported() -> None:
    mapping, excluded = match_categories({1: "Person", 2: "robot", 3: "cup"}, ("person", "cup"))
    assert mapping == {"person": 1, "cup": 3} and excluded == ("robot",)
    dets = {1: _dets([("person", 0.9, [0, 0, 5, 5]), ("dog", 0.9, [0, 0, 5, 5])])}
    assert [r["category_id"] for r in to_results(dets, MODEL_NAMES, mapping)] == [1]


def test_nothing_to_score_is_a_dataset_error() -> None:
    with pytest.raises(DatasetError, match="no labelled boxes"):
        evaluate(_gt([]), [])


def test_no_detections_scores_zero() -> None:
    report = evaluate(_gt([(1, 1, [10, 10, 50, 80])]), [])
    assert report.map50 == 0.0 and report.precision == 0.0 and report.recall == 0.0
