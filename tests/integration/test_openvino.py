"""The OpenVINO backend on the default model and real photos: FP32 against ONNX Runtime, and
NNCF INT8 calibrated on the scikit-image sample photos."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import pytest
from skimage import data

from common.letterbox import Preprocessor
from modelprep.quantize.head import head_nodes
from modelprep.quantize.nncf_int8 import quantize
from perception.pipeline import Detector
from tests.integration.test_detect_real import CHELSEA_CAT, COFFEE_CUP, bgr, box_iou

pytestmark = pytest.mark.integration

PHOTOS = [("chelsea", "cat", CHELSEA_CAT), ("coffee", "cup", COFFEE_CUP)]
#: Twelve sample photos (colour and grey), each also mirrored: 24 calibration frames.
CALIBRATION = (
    *("astronaut", "chelsea", "coffee", "rocket", "cat", "immunohistochemistry"),
    *("hubble_deep_field", "retina", "colorwheel", "camera", "coins", "clock"),
)


def sample_bgr(name: str) -> npt.NDArray[np.uint8]:
    image = getattr(data, name)()
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    return np.ascontiguousarray(image[:, :, ::-1])


def calibration_frames(height: int, width: int) -> list[npt.NDArray[np.float32]]:
    """The calibration photos letterboxed exactly as the pipeline does, one [1,3,H,W] each."""
    pre = Preprocessor(height, width, 1)
    frames = []
    for name in CALIBRATION:
        image = sample_bgr(name)
        for view in (image, np.ascontiguousarray(image[:, ::-1])):
            batch, _ = pre.run([view])
            frames.append(batch.copy())  # the preprocessor reuses its buffer
    return frames


@pytest.fixture(scope="module")
def detectors(default_model: Path) -> Iterator[tuple[Detector, Detector]]:
    with (
        Detector.open(default_model) as reference,
        Detector.open(default_model, backend="openvino", precision="fp32") as candidate,
    ):
        yield reference, candidate


@pytest.mark.parametrize(("photo", "expected", "hand_box"), PHOTOS)
def test_fp32_finds_the_object_and_agrees_with_onnx_runtime(
    detectors: tuple[Detector, Detector], photo: str, expected: str, hand_box: tuple[float, ...]
) -> None:
    reference, candidate = detectors
    assert (candidate.backend.name, candidate.backend.precision) == ("openvino", "fp32")
    ours, theirs = candidate.detect(bgr(photo)), reference.detect(bgr(photo))
    assert ours.class_names[0] == expected
    assert box_iou(ours.xyxy[0].tolist(), hand_box) >= 0.5
    assert ours.class_names == theirs.class_names
    for a, b in zip(ours.xyxy.tolist(), theirs.xyxy.tolist(), strict=True):
        assert box_iou(a, b) >= 0.9


def test_nncf_int8_still_finds_the_cat_and_the_cup(default_model: Path, tmp_path: Path) -> None:
    keep = head_nodes(default_model)
    ir = tmp_path / "int8.xml"
    quantize(default_model, ir, calibration_frames(640, 640), keep_float=keep)
    with Detector.open(ir, backend="openvino", precision="int8") as det:
        assert det.backend.precision == "int8"
        assert det.info.input_height == 640 and det.names[0] == "person"  # metadata kept
        for photo, expected, hand_box in PHOTOS:
            result = det.detect(bgr(photo))
            assert result.class_names[0] == expected, (photo, result.class_names)
            assert box_iou(result.xyxy[0].tolist(), hand_box) >= 0.5
