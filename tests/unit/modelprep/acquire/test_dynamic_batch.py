"""The translator's dynamic batch: a model converted with ``dynamic_batch`` takes any batch,
and each image of a batch comes out as the batch-1 model gives it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import onnx
import onnxruntime as ort
import pytest

from common.errors import ModelError
from modelprep.acquire.tfjs_graph import load_tfjs_graph
from modelprep.acquire.tfjs_to_onnx import build_onnx_model, save_onnx
from tests.unit.modelprep.acquire.tfjs_models import TfjsModel, fused_conv

RNG = np.random.default_rng(11)


def _rand(*shape: int) -> npt.NDArray[np.float32]:
    return RNG.standard_normal(shape).astype(np.float32)


def _head(out_size: tuple[int, int]) -> tuple[TfjsModel, str]:
    """A YOLOv5-like graph: conv, a resize (to ``out_size``), the detect head's reshape,
    transpose and strided slices, and the final flattening reshape."""
    m = TfjsModel((1, 4, 5, 3))
    conv = fused_conv(m, "conv", "input_1", _rand(1, 1, 3, 12), _rand(12))
    up = m.op(
        "up",
        "ResizeNearestNeighbor",
        [conv, m.const("size", out_size, np.int32)],
        half_pixel_centers=True,
    )
    cells = out_size[0] * out_size[1]
    rs = m.op("rs", "Reshape", [up, m.const("shape", [-1, cells, 2, 6], np.int32)])
    tr = m.op("tr", "Transpose", [rs, m.const("perm", [0, 2, 1, 3], np.int32)])
    consts = [m.const(f"s/{i}", v, np.int32) for i, v in enumerate(([0, 0], [0, 4], [1, 1]))]
    box = m.op("box", "StridedSlice", [tr, *consts], ellipsis_mask=1)
    out = m.op("flat", "Reshape", [box, m.const("shape2", [-1, 2 * cells, 4], np.int32)])
    return m, out


def convert_tfjs_to_onnx(
    model_json: Path,
    path: Path,
    *,
    names: list[str],
    metadata: dict[str, str],
    dynamic_batch: bool = False,
) -> None:
    """The fetch's own steps: the TF.js graph, translated, then saved."""
    graph = load_tfjs_graph(model_json)
    save_onnx(build_onnx_model(graph, names=names, metadata=metadata, dynamic_batch=dynamic_batch),
              path)  # fmt: skip


def _convert(tmp_path: Path, model: TfjsModel, out: str, dynamic: bool) -> ort.InferenceSession:
    folder = tmp_path / ("dynamic" if dynamic else "static")
    folder.mkdir()
    path = folder / "model.onnx"
    convert_tfjs_to_onnx(
        model.write(folder, out), path, names=["a"], metadata={}, dynamic_batch=dynamic
    )
    return ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])


@pytest.mark.parametrize("out_size", [(8, 10), (7, 9)])  # integer scales; sizes
def test_a_batch_gives_each_image_what_the_batch_1_model_gives(
    tmp_path: Path, out_size: tuple[int, int]
) -> None:
    model, out = _head(out_size)
    static = _convert(tmp_path, model, out, dynamic=False)
    dynamic = _convert(tmp_path, model, out, dynamic=True)
    images = _rand(3, 3, 4, 5)  # NCHW, as the graph's input is exposed
    singles = [static.run(None, {"images": images[i : i + 1]})[0] for i in range(3)]
    batched = dynamic.run(None, {"images": images})[0]
    assert batched.shape == (3, *singles[0].shape[1:])
    np.testing.assert_array_equal(batched, np.concatenate(singles))
    np.testing.assert_array_equal(dynamic.run(None, {"images": images[:1]})[0], singles[0])


def test_the_batch_is_named_and_denoted_in_the_input_and_output(tmp_path: Path) -> None:
    model, out = _head((8, 10))
    _convert(tmp_path, model, out, dynamic=True)
    graph = onnx.load(str(tmp_path / "dynamic" / "model.onnx")).graph

    def dims(value: Any) -> list[Any]:
        return [d.dim_param or d.dim_value for d in value.type.tensor_type.shape.dim]

    assert dims(graph.input[0]) == ["batch", 3, 4, 5]
    assert dims(graph.output[0]) == ["batch", 160, 4]
    for value in (graph.input[0], graph.output[0]):
        assert value.type.tensor_type.shape.dim[0].denotation == "DATA_BATCH"
    # A static conversion keeps the graph's batch of 1.
    model, out = _head((8, 10))
    _convert(tmp_path, model, out, dynamic=False)
    static = onnx.load(str(tmp_path / "static" / "model.onnx")).graph
    assert dims(static.input[0]) == [1, 3, 4, 5]


@pytest.mark.parametrize(
    ("op", "const", "message"),
    [
        ("Transpose", [1, 0, 2, 3], "moves the batch axis"),
        ("Reshape", [20, 3], "moves the batch axis"),
    ],
)
def test_an_op_that_moves_the_batch_is_a_model_error(
    tmp_path: Path, op: str, const: list[int], message: str
) -> None:
    m = TfjsModel((1, 4, 5, 3))
    out = m.op("x", op, ["input_1", m.const("c", const, np.int32)])
    with pytest.raises(ModelError, match=message):
        convert_tfjs_to_onnx(
            m.write(tmp_path, out), tmp_path / "m.onnx", names=[], metadata={}, dynamic_batch=True
        )
    # Without a dynamic batch the same graph converts.
    convert_tfjs_to_onnx(m.write(tmp_path, out), tmp_path / "m.onnx", names=[], metadata={})


def test_a_strided_slice_of_the_batch_is_a_model_error(tmp_path: Path) -> None:
    m = TfjsModel((1, 4, 5, 3))
    consts = [m.const(f"c{i}", v, np.int32) for i, v in enumerate(([0], [1], [1]))]
    out = m.op("x", "StridedSlice", ["input_1", *consts], shrink_axis_mask=1)
    with pytest.raises(ModelError, match="slices the batch axis"):
        convert_tfjs_to_onnx(
            m.write(tmp_path, out), tmp_path / "m.onnx", names=[], metadata={}, dynamic_batch=True
        )
