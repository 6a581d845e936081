"""ONNX Runtime's INT8 quantizer, run on a small real graph: it works, and its advice to
pre-process the model stays out of our log."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest
from onnx import TensorProto, helper, numpy_helper

from modelprep.quantize.ort_int8 import quantize


def _conv_model(path: Path) -> None:
    weight = numpy_helper.from_array(
        np.random.default_rng(0).normal(size=(4, 3, 3, 3)).astype(np.float32), "w"
    )
    graph = helper.make_graph(
        [helper.make_node("Conv", ["images", "w"], ["out"], pads=[1, 1, 1, 1])],
        "tiny",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 8, 8])],
        [helper.make_tensor_value_info("out", TensorProto.FLOAT, [1, 4, 8, 8])],
        [weight],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    onnx.save(model, str(path))


def test_quantize_without_the_preprocessing_advice(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    src, out = tmp_path / "tiny.onnx", tmp_path / "tiny-int8.onnx"
    _conv_model(src)
    frames = [np.random.default_rng(i).random((1, 3, 8, 8), np.float32) for i in range(4)]
    with caplog.at_level(logging.WARNING):
        quantize(src, out, frames, keep_float=[])
    assert not [r for r in caplog.records if "pre-processing" in r.getMessage()], caplog.text
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    assert session.run(None, {"images": frames[0]})[0].shape == (1, 4, 8, 8)
    props = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    assert props["precision"] == "int8"
    # The filter is gone afterwards: other warnings on the root logger still reach the log.
    logging.getLogger().warning("Please consider to run pre-processing before quantization")
    assert "pre-processing" in caplog.text
