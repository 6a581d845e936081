"""A model whose outputs are not finite gives no detections and says so, on the real backend."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from perception.decode import sane_outputs
from perception.pipeline import Detector

ANCHORS = 16


def constant_model(tmp_path: Path, scale: float) -> Path:
    """A YOLOv8-layout model ``[1, 4 + 2, 16]`` with one confident box, every value times
    ``scale`` (NaN and 1e30 stand for a broken conversion)."""
    out = np.zeros((1, 6, ANCHORS), np.float32)
    out[0, :4, 3] = (16, 16, 8, 8)  # cx, cy, w, h in the 32x32 input
    out[0, 4, 3] = 0.9  # class 0's score
    zeros = np.zeros((3 * 32 * 32, 6 * ANCHORS), np.float32)
    graph = helper.make_graph(
        [
            helper.make_node("Flatten", ["images"], ["flat"]),
            helper.make_node("MatMul", ["flat", "w"], ["zero"]),
            helper.make_node("Reshape", ["zero", "shape"], ["zero3"]),
            helper.make_node("Add", ["zero3", "bias"], ["raw"]),
            helper.make_node("Mul", ["raw", "scale"], ["output0"]),
        ],
        "constant",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 32, 32])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, 6, ANCHORS])],
        [
            numpy_helper.from_array(zeros, "w"),
            numpy_helper.from_array(np.array([1, 6, ANCHORS], np.int64), "shape"),
            numpy_helper.from_array(out, "bias"),
            numpy_helper.from_array(np.array(scale, np.float32), "scale"),
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    helper.set_model_props(model, {"names": "{0: 'a', 1: 'b'}", "imgsz": "[32, 32]"})
    path = tmp_path / f"scale_{scale}.onnx"
    onnx.save(model, str(path))
    return path


@pytest.mark.parametrize("scale, sane", [(1.0, True), (math.nan, False), (1e30, False)])
def test_nonfinite_outputs_are_flagged_not_decoded(
    tmp_path: Path, scale: float, sane: bool
) -> None:
    with Detector.open(constant_model(tmp_path, scale), backend="onnx") as det:
        result = det.detect(np.full((32, 32, 3), 100, np.uint8))
    assert result.output_sane is sane
    assert len(result) == (1 if sane else 0)


def test_sane_outputs_per_image() -> None:
    batch = np.zeros((3, 6, 4), np.float32)
    batch[1, 0, 0] = np.inf
    batch[2, 5, 3] = -2e6
    assert sane_outputs(batch).tolist() == [True, False, False]
    assert sane_outputs(np.full((1, 6, 4), np.nan, np.float32)).tolist() == [False]
