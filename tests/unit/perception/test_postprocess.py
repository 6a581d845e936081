"""Class-aware NMS against a brute-force reference, the class filter, top-k, the result type
that post-processing produces and the settings it reads."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from common.boxes import Boxes
from common.errors import ConfigError
from perception.decode import decode_end2end
from perception.postprocess import class_mask, nms, select
from perception.types import DetectionResult
from services.detector.contract import DetectorSettings


def iou(a: list[float], b: list[float]) -> float:
    iw = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    ih = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = iw * ih
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def brute_force_nms(boxes: list[list[float]], scores: list[float], classes: list[int],
                    threshold: float) -> list[int]:  # fmt: skip
    """Textbook greedy NMS, one box at a time, in pure Python."""
    kept: list[int] = []
    for i in sorted(range(len(scores)), key=lambda k: -scores[k]):
        if all(classes[i] != classes[j] or iou(boxes[i], boxes[j]) <= threshold for j in kept):
            kept.append(i)
    return kept


def random_boxes(
    seed: int, n: int, num_classes: int
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.int32]]:
    """Boxes clustered around a few centres, so that many of them overlap."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(50, 590, (5, 2))
    xy = centres[rng.integers(0, 5, n)] + rng.normal(0, 15, (n, 2))
    wh = rng.uniform(10, 120, (n, 2))
    xyxy = np.concatenate([xy - wh / 2, xy + wh / 2], axis=1).astype(np.float32)
    scores = rng.uniform(0.01, 1.0, n).astype(np.float32)
    return xyxy, scores, rng.integers(0, num_classes, n).astype(np.int32)


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("threshold", [0.3, 0.45, 0.7])
def test_nms_matches_brute_force(seed: int, threshold: float) -> None:
    xyxy, scores, classes = random_boxes(seed, n=150, num_classes=3)
    expected = brute_force_nms(xyxy.tolist(), scores.tolist(), classes.tolist(), threshold)
    assert nms(xyxy, scores, classes, threshold).tolist() == expected


def test_nms_is_class_aware() -> None:
    box = [10.0, 10.0, 50.0, 50.0]
    xyxy = np.array([box, box, box], np.float32)
    scores = np.array([0.9, 0.8, 0.7], np.float32)
    assert nms(xyxy, scores, np.array([0, 1, 0], np.int32), 0.45).tolist() == [0, 1]
    assert nms(xyxy[:0], scores[:0], np.zeros(0, np.int32), 0.45).tolist() == []


def test_select_caps_detections_and_sorts_by_score() -> None:
    xyxy, scores, classes = random_boxes(0, n=200, num_classes=80)
    cands = Boxes(xyxy=xyxy, scores=scores, class_ids=classes)
    picked = select(cands, iou=0.45, max_det=5, apply_nms=True)
    assert picked.scores.shape == (5,)
    assert np.all(np.diff(picked.scores) <= 0)
    full = select(cands, iou=0.45, max_det=300, apply_nms=True)
    np.testing.assert_array_equal(picked.xyxy, full.xyxy[:5])


def test_select_without_nms_keeps_overlaps() -> None:
    xyxy = np.array([[0, 0, 10, 10], [0, 0, 10, 10]], np.float32)
    c = Boxes(xyxy=xyxy, scores=np.array([0.5, 0.9], np.float32), class_ids=np.zeros(2, np.int32))
    out = select(c, iou=0.45, max_det=10, apply_nms=False)
    np.testing.assert_allclose(out.scores, [0.9, 0.5])


def test_class_mask() -> None:
    names = ("person", "bicycle", "cup")
    assert class_mask(names, None) is None
    np.testing.assert_array_equal(class_mask(names, ("cup", "person")), [True, False, True])
    with pytest.raises(ConfigError) as info:
        class_mask(names, ("cup", "kitten"))
    assert str(info.value) == "unknown class name(s) 'kitten'; valid names: person, bicycle, cup"


# --- DetectionResult / DetectorSettings ---------------------------------------------------------


def test_detection_result_validates_shapes_saying_what_was_expected() -> None:
    ok = DetectionResult(
        boxes=Boxes(
            xyxy=np.zeros((2, 4), np.float32),
            scores=np.zeros(2, np.float32),
            class_ids=np.array([0, 1], np.int32),
        ),
        names=("a", "b"),
    )
    assert len(ok) == 2 and ok.class_names == ["a", "b"]
    assert ok.xyxy is ok.boxes.xyxy and ok.scores is ok.boxes.scores
    assert len(DetectionResult()) == 0
    # The arrays are checked by Boxes (common/boxes.py), the one place that checks them.
    with pytest.raises(ValueError, match=r"xyxy must be an \(n, 4\) float32 array"):
        DetectionResult(boxes=Boxes(xyxy=np.zeros((2, 5), np.float32)))
    with pytest.raises(ValueError, match=r"scores must be a \(2,\) float32 array"):
        DetectionResult(
            boxes=Boxes(xyxy=np.zeros((2, 4), np.float32), scores=np.zeros(3, np.float32))
        )
    with pytest.raises(ValueError, match=r"class_ids must lie in 0..1"):
        DetectionResult(
            boxes=Boxes(
                xyxy=np.zeros((1, 4), np.float32),
                scores=np.zeros(1, np.float32),
                class_ids=np.array([2], np.int32),
            ),
            names=("a", "b"),
        )


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"conf": 1.5}, r"detector\.conf must be within 0\.\.1, got 1.5"),
        ({"conf": -0.1}, "detector.conf must be"),
        ({"iou": float("nan")}, "detector.iou must be"),
        ({"max_det": 0}, r"detector\.max_det must be within 1\.\.10000, got 0"),
        ({"classes": ("cup", "")}, "non-empty class names"),
    ],
)
def test_detector_settings_validation(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        DetectorSettings(**kwargs)  # type: ignore[arg-type]


def test_detector_settings_have_one_default_per_threshold() -> None:
    s = DetectorSettings()
    assert (s.conf, s.iou, s.max_det, s.classes) == (0.25, 0.45, 100, ())  # () keeps all


def test_a_non_finite_or_inverted_box_does_not_wipe_out_the_frame() -> None:
    good = np.array([[75, 270, 125, 370], [475, 270, 525, 370]], np.float32)
    bad = np.array([[np.nan, 260, np.inf, 340], [300, 300, 200, 200]], np.float32)
    # End-to-end rows (x1, y1, x2, y2, score, class) as a model might emit them: the decoder
    # drops the two that are not boxes, so NMS sees only the good ones.
    rows = np.hstack(
        [
            np.vstack([good, bad]),
            np.array([[0.9, 0], [0.8, 2], [0.99, 0], [0.95, 9]], np.float32),
        ]
    )[None]
    (cands,) = decode_end2end(rows, conf=0.25, num_classes=10)
    kept = select(cands, iou=0.45, max_det=10, apply_nms=True)
    np.testing.assert_array_equal(kept.xyxy, good)
    assert kept.class_ids.tolist() == [0, 2]
