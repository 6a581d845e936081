"""A tiny model whose boxes depend on the image, for tests of batching and rounds: one box in
the left half of a 32x32 input, scored by that half's brightness, one in the right half."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
import onnx
from onnx import TensorProto, helper, numpy_helper

SIDE, ANCHORS = 32, 16
LEFT, RIGHT = 3, 9  # the anchors whose score is the brightness of the image's left, right half


def halves_model(tmp_path: Path, batch: int | str = "batch") -> Path:
    """A YOLOv8-layout model ``[B, 4 + 2, 16]``: one box in the left half of the 32x32 input
    scored by that half's mean brightness (0..1), one in the right half likewise."""
    weights = np.zeros((3, SIDE, SIDE, 6, ANCHORS), np.float32)  # NCHW pixel -> output value
    half = 1.0 / (3 * SIDE * SIDE // 2)
    weights[:, :, : SIDE // 2, 4, LEFT] = half
    weights[:, :, SIDE // 2 :, 4, RIGHT] = half
    boxes = np.zeros((1, 6, ANCHORS), np.float32)
    boxes[0, :4, LEFT] = (8, 16, 12, 12)  # cx, cy, w, h in input pixels
    boxes[0, :4, RIGHT] = (24, 16, 12, 12)
    graph = helper.make_graph(
        [
            helper.make_node("Flatten", ["images"], ["flat"]),
            helper.make_node("MatMul", ["flat", "w"], ["scores"]),
            helper.make_node("Reshape", ["scores", "shape"], ["scores3"]),
            helper.make_node("Add", ["scores3", "boxes"], ["output0"]),
        ],
        "halves",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [batch, 3, SIDE, SIDE])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [batch, 6, ANCHORS])],
        [
            numpy_helper.from_array(weights.reshape(3 * SIDE * SIDE, 6 * ANCHORS), "w"),
            numpy_helper.from_array(np.array([-1, 6, ANCHORS], np.int64), "shape"),
            numpy_helper.from_array(boxes, "boxes"),
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    helper.set_model_props(model, {"names": "{0: 'a', 1: 'b'}", "imgsz": f"[{SIDE}, {SIDE}]"})
    path = tmp_path / f"halves-{batch}.onnx"
    onnx.save(model, str(path))
    return path


def image(left: bool, right: bool) -> npt.NDArray[np.uint8]:
    img = np.zeros((SIDE, SIDE, 3), np.uint8)
    img[:, : SIDE // 2] = 255 if left else 0
    img[:, SIDE // 2 :] = 255 if right else 0
    return img
