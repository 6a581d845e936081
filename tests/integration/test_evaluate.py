"""`evaluate` with the real default model on the hand-labelled scikit-image photos."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from faster_coco_eval import COCO, COCOeval_faster

from perception.pipeline import Detector
from services.detector.contract import DetectorSettings
from tools.evaluation.data.write_images import ANNOTATIONS, write_images
from tools.evaluation.datasets import load_dataset
from tools.evaluation.evaluate import DEFAULT_EVAL_CONF, EVAL_MAX_DET, detect_dataset, score

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[2]
# Measured 0.852 mAP50 (0.547 mAP50-95) with the default YOLOv5s on onnx/cpu; see
# docs/evaluation.md. The floor leaves room for another runtime's rounding, not for a bug.
MAP50_FLOOR = 0.7
LABELLED = {"person", "cat", "cup", "spoon", "dining table", "motorcycle", "bicycle", "bench",
            "bottle"}  # fmt: skip


@pytest.fixture(scope="module")
def images(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("skimage_coco")
    write_images(folder)
    return folder


def _silent(*_args: object) -> None:
    """The evaluator prints its tables; the test compares numbers."""


def test_evaluate_command_on_the_labelled_photos(images: Path, default_model: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "tools.evaluation", "evaluate", "--dataset", str(ANNOTATIONS),
         "--images", str(images), "--model", str(default_model), "--json"],
        cwd=REPO, capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert (report["images"], report["labels"]) == (6, 10)
    assert set(report["per_class"]) == LABELLED
    assert report["map50"] >= MAP50_FLOOR, report
    assert 0 < report["map50_95"] < report["map50"]
    # The big, clear objects are found at the stack's own threshold.
    for name in ("person", "cat", "cup", "motorcycle"):
        assert report["per_class"][name]["recall"] == 1.0, (name, report["per_class"][name])


def test_evaluate_agrees_with_the_evaluator_on_the_same_detections(
    images: Path, default_model: Path
) -> None:
    dataset = load_dataset(ANNOTATIONS, images)
    settings = DetectorSettings(conf=DEFAULT_EVAL_CONF, max_det=EVAL_MAX_DET)  # as the command
    with Detector.open(default_model, settings=settings) as detector:
        detections = detect_dataset(detector, dataset)
        names = detector.names
    ours = score(dataset, names, detections)

    # The same detections, straight into faster-coco-eval with the shipped file as ground truth.
    coco_gt = COCO(str(ANNOTATIONS))
    category = {c["name"]: c["id"] for c in coco_gt.dataset["categories"]}
    results = [
        {"image_id": image_id, "category_id": category[names[c]], "score": float(s),
         "bbox": [float(x1), float(y1), float(x2 - x1), float(y2 - y1)]}
        for image_id, boxes in detections.items()
        for c, s, (x1, y1, x2, y2) in zip(boxes.class_ids, boxes.scores, boxes.xyxy, strict=True)
    ]  # fmt: skip
    direct = COCOeval_faster(coco_gt, coco_gt.loadRes(results), "bbox", print_function=_silent)
    direct.evaluate()
    direct.accumulate()
    direct.summarize()
    assert ours.map50_95 == direct.stats[0]
    assert ours.map50 == direct.stats[1]
    precision = direct.eval["precision"][:, :, :, 0, -1]  # area "all", 100 detections
    names_by_id = {c["id"]: c["name"] for c in coco_gt.dataset["categories"]}
    checked = 0
    for k, cid in enumerate(direct.params.catIds):
        p = precision[:, :, k]
        if (p > -1).any():
            assert ours.per_class[names_by_id[cid]].ap50_95 == p[p > -1].mean()
            assert ours.per_class[names_by_id[cid]].ap50 == p[0][p[0] > -1].mean()
            checked += 1
    assert checked == len(LABELLED)
