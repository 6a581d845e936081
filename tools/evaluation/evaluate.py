"""``python -m tools.evaluation``: run a model over a labelled dataset and score it.

The dataset is checked completely before the model is loaded, so a typo in a label costs a
second, not a model run. Detections are made at a low confidence floor (``--conf``, 0.001) for
mAP; ``--conf-threshold`` (0.25, the stack's default) is where precision and recall are read.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.boxes import Boxes
from common.lifecycle import Progress, print_progress
from services.detector.contract import DetectorSettings
from tools.evaluation.accuracy import (
    DEFAULT_CONF_THRESHOLD,
    AccuracyReport,
    evaluate,
    match_categories,
    to_results,
)
from tools.evaluation.datasets import load_dataset
from tools.evaluation.labelled import DatasetError, LabelledSet

#: Confidence floor for the detections fed to mAP (the usual value for COCO evaluation).
DEFAULT_EVAL_CONF = 0.001


#: Detections kept per image when scoring, as Ultralytics evaluates (300).
EVAL_MAX_DET = 300


def detect_dataset(
    detector: Any, dataset: LabelledSet, progress: Progress | None = None
) -> dict[int, Boxes]:
    """Run ``detector`` (a perception Detector) on every image of ``dataset``: the
    boxes found in each, by image id; their class ids index ``detector.names``.

    Raises DatasetError when an image's real size differs from the size its labels assume.
    """
    from common.images import load_image

    out: dict[int, Boxes] = {}
    for n, item in enumerate(dataset.images, 1):
        image = load_image(item.path)
        height, width = image.shape[:2]
        if (width, height) != (item.width, item.height):
            raise DatasetError(
                f"{dataset.source}: image {item.path} is {width}x{height}, "
                f"but its labels are for {item.width}x{item.height}"
            )
        out[item.id] = detector.detect(image).boxes
        if progress is not None and n % 100 == 0:
            progress(f"evaluate: {n}/{len(dataset.images)} images")
    return out


def ground_truth_for(
    dataset: LabelledSet, model_names: tuple[str, ...]
) -> tuple[dict[str, Any], dict[str, int], tuple[str, ...]]:
    """The ground truth of the classes the model knows, the name -> category id map, and the
    categories left out. DatasetError when no labelled box is left to score."""
    name_to_category, excluded = match_categories(dataset.categories, model_names)
    ground_truth = dataset.ground_truth(set(name_to_category.values()))
    if not any(not a["iscrowd"] for a in ground_truth["annotations"]):
        unknown = f" (the model has no {', '.join(excluded)})" if excluded else ""
        raise DatasetError(f"{dataset.source}: no labelled box of a class the model knows{unknown}")
    return ground_truth, name_to_category, excluded


def score(
    dataset: LabelledSet,
    model_names: tuple[str, ...],
    detections: Mapping[int, Boxes],
    conf_threshold: float = DEFAULT_CONF_THRESHOLD,
) -> AccuracyReport:
    """Score ``detections`` of ``dataset`` (boxes by image id) for a model with
    ``model_names``, which its class ids index (matched to the dataset by class name)."""
    ground_truth, name_to_category, excluded = ground_truth_for(dataset, model_names)
    results = to_results(detections, model_names, name_to_category)
    return evaluate(ground_truth, results, conf_threshold, excluded)


def format_text(report: AccuracyReport, dataset: str) -> str:
    """A table a person reads: the headline figures, then one row per class."""
    lines = [
        f"{dataset}: {report.images} images, {report.labels} labelled boxes",
        f"mAP50 {report.map50:.3f}  mAP50-95 {report.map50_95:.3f}  "
        f"precision {report.precision:.3f}  recall {report.recall:.3f} "
        f"(at conf >= {report.conf_threshold:g})",
        "",
        f"{'class':<16} {'labels':>6} {'AP50':>6} {'AP50-95':>8} {'P':>6} {'R':>6}",
    ]
    for name, c in sorted(report.per_class.items()):
        lines.append(
            f"{name:<16} {c.labels:>6} {c.ap50:>6.3f} {c.ap50_95:>8.3f} "
            f"{c.precision:>6.3f} {c.recall:>6.3f}"
        )
    if report.excluded_categories:
        unknown = ", ".join(report.excluded_categories)
        lines += ["", f"not scored (the model has no such class): {unknown}"]
    return "\n".join(lines)


def _check_fraction(name: str, value: float) -> None:
    if not 0.0 <= value <= 1.0:
        raise DatasetError(f"{name} must be within 0..1, got {value}")


@dataclass(frozen=True, slots=True, kw_only=True)
class EvaluateOptions:
    """What ``evaluate`` was asked: the dataset, the model and its backend, the thresholds
    (``conf``: the floor of the detections fed to mAP; ``conf_threshold``: where precision and
    recall are read), and the output."""

    dataset: str  # a COCO JSON file or a YOLO folder
    images: str | None  # COCO: the folder its file_names are relative to
    model: str | None  # None: the default model, fetched
    backend: str
    conf: float
    iou: float
    conf_threshold: float
    as_json: bool


def run(options: EvaluateOptions) -> int:
    """The ``evaluate`` command: load, detect, score, print."""
    from modelprep.files import ensure_default_model
    from perception import Detector

    for name, value in (
        ("--conf", options.conf),
        ("--iou", options.iou),
        ("--conf-threshold", options.conf_threshold),
    ):
        _check_fraction(name, value)
    dataset = load_dataset(options.dataset, options.images)
    model = Path(options.model) if options.model else ensure_default_model(progress=print_progress)
    # Ultralytics' own max_det for evaluation (the stack's default keeps 100): COCO then keeps
    # the best 100 per image and class.
    settings = DetectorSettings(conf=options.conf, iou=options.iou, max_det=EVAL_MAX_DET)
    with Detector.open(model, backend=options.backend, settings=settings) as detector:
        names = detector.names
        ground_truth_for(dataset, names)  # before the run: nothing to score is an error now
        detections = detect_dataset(detector, dataset, print_progress)
    report = score(dataset, names, detections, options.conf_threshold)
    if report.excluded_categories:
        unknown = ", ".join(report.excluded_categories)
        print_progress(f"evaluate: not scored, the model has no such class: {unknown}")
    if options.as_json:
        extra = {"dataset": str(dataset.source), "model": str(model), "backend": options.backend}
        print(json.dumps({**report.to_json_dict(), **extra}))
    else:
        print(format_text(report, str(dataset.source)))
    return 0
