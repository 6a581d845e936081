"""The nodes INT8 keeps in float: the detect layer and what it feeds, found by name."""

from __future__ import annotations

from pathlib import Path

import onnx
import pytest
from onnx import TensorProto, helper

from common.errors import ModelError
from services.detector.quantize.head import head_nodes


def chain(*names: str) -> onnx.ModelProto:
    """A chain of Relu nodes called ``names``: each feeds the next, the last is the output."""
    nodes = [
        helper.make_node("Relu", [f"t{i}"], [f"t{i + 1}"], name=name)
        for i, name in enumerate(names)
    ]
    info = [
        helper.make_tensor_value_info(n, TensorProto.FLOAT, [1]) for n in ("t0", f"t{len(names)}")
    ]
    return helper.make_model(helper.make_graph(nodes, "g", [info[0]], [info[1]]))


def test_the_default_model_keeps_its_detect_layer_and_output_scale(default_model: Path) -> None:
    model = onnx.load(str(default_model), load_external_data=False)
    kept = head_nodes(model)
    assert kept[-1] == "output0/Mul"  # the box scale, outside the tf_detect scope
    assert all("/tf_detect/" in n for n in kept[:-1])
    assert {n.name for n in model.graph.node if "/tf_detect/" in n.name} == set(kept[:-1])
    assert sum(n.op_type == "Conv" for n in model.graph.node if n.name in kept) == 3


def test_an_ultralytics_export_keeps_its_last_module_and_what_follows() -> None:
    model = chain("/model.0/conv/Conv", "/model.9/m/Relu", "/model.22/Mul", "/model.22/Cat", "out")
    assert head_nodes(model) == ["/model.22/Mul", "/model.22/Cat", "out"]


def test_a_model_without_a_named_head_is_refused() -> None:
    with pytest.raises(ModelError, match="cannot find the detection head"):
        head_nodes(chain("a", "b"))
