"""Translate a TF.js graph model into an ONNX model that ONNX Runtime and TensorRT run well.

Layout: TensorFlow computes in NHWC, ONNX Conv/MaxPool/Resize in NCHW. Wrapping every conv in
a pair of Transposes would work but costs copies, so instead each translated tensor carries a
layout tag. A 4-D feature map is kept in NCHW (``Layout.NCHW``) while its *shape* is still
recorded in TF's NHWC terms; axis-dependent ops (Concat, Pad, Resize, constants broadcast in
elementwise ops) remap their axes. Ops whose meaning depends on the memory order (Reshape,
Transpose, StridedSlice) get a ``Layout.NATIVE`` input, converted by one cached Transpose. For
YOLOv5 that adds just one Transpose per detection head, before its Reshape.

Batch: the TF.js graph declares a batch of 1. With ``dynamic_batch`` the ONNX graph takes any
batch instead: its input and output name axis 0 ``batch``, and every shape the graph writes
down copies the batch from its input (a Reshape target's leading 1 becomes 0, "keep this
dimension"; a Resize to sizes takes the batch from ``Shape``). An op that would mix the batch
with another axis is a ModelError.

Scope: single-input, single-output graphs with static shapes, float32 data; the op table
(``TRANSLATORS`` in tfjs_ops.py) covers what the TF.js converter emits for YOLOv5. Anything else
raises ModelError naming the op.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import onnx
from onnx import helper

from common.errors import ModelError
from modelprep.acquire.tfjs_graph import TfGraph, TfNode
from modelprep.acquire.tfjs_onnx_builder import GraphBuilder, Layout
from modelprep.acquire.tfjs_ops import TRANSLATORS

OPSET = 17  # Resize-13 semantics, and parsed by TensorRT 8.6+/10
IR_VERSION = 8  # the IR that opset 17 shipped with; older runtimes reject newer IRs


def build_onnx_model(
    graph: TfGraph,
    *,
    names: Sequence[str],
    metadata: Mapping[str, str],
    box_scale: Sequence[float] | None = None,
    input_name: str = "images",
    output_name: str = "output0",
    dynamic_batch: bool = False,
) -> onnx.ModelProto:
    """Translate ``graph`` into a checked in-memory ONNX model.

    ``names`` becomes the Ultralytics-style ``names`` metadata ("{0: 'person', ...}").
    ``box_scale`` (4 factors) multiplies channels 0..3 of the output's last axis, turning the
    TF.js normalised cx, cy, w, h into input pixels like Ultralytics' own ONNX export.
    """
    if len(graph.inputs) != 1 or len(graph.outputs) != 1:
        raise ModelError(
            f"expected one input and one output, got {list(graph.inputs)} and {list(graph.outputs)}"
        )
    builder = GraphBuilder(graph.constants, dynamic_batch=dynamic_batch)
    ((tf_input, shape),) = graph.inputs.items()
    graph_input = builder.define_input(tf_input, input_name, shape)
    for node in _reachable_nodes(graph):
        translator = TRANSLATORS.get(node.op)
        if translator is None:
            raise ModelError(f"unsupported TF.js op {node.op} (node {node.name})")
        translator(builder, node)
    graph_output = _finish_output(builder, graph.outputs[0], output_name, box_scale)
    onnx_graph = helper.make_graph(
        builder.nodes, "tfjs_graph", [graph_input], [graph_output], initializer=builder.initializers
    )
    model = helper.make_model(
        onnx_graph,
        opset_imports=[helper.make_opsetid("", OPSET)],
        producer_name="modelprep.acquire.tfjs_to_onnx",
    )
    model.ir_version = IR_VERSION
    props = {"names": str(dict(enumerate(names))), **metadata}
    helper.set_model_props(model, props)
    try:
        onnx.checker.check_model(model, full_check=True)
    except (onnx.checker.ValidationError, onnx.shape_inference.InferenceError) as exc:
        first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ModelError(f"translated graph failed the ONNX checker: {first_line}") from exc
    return model


def save_onnx(model: onnx.ModelProto, out_path: Path) -> None:
    """Write ``model`` to ``out_path``; a file that cannot be written is a ModelError."""
    try:
        onnx.save(model, str(out_path))
    except OSError as exc:
        raise ModelError(f"cannot write {out_path}: {exc.strerror or exc}") from exc


def _reachable_nodes(graph: TfGraph) -> list[TfNode]:
    """The nodes the output depends on, producers first (GraphDef order is not guaranteed)."""
    by_name = {node.name: node for node in graph.nodes}
    ordered: list[TfNode] = []
    state: dict[str, bool] = {}  # False: being visited, True: done
    stack: list[tuple[str, bool]] = [(graph.outputs[0], False)]
    while stack:
        name, expanded = stack.pop()
        if expanded:
            state[name] = True
            ordered.append(by_name[name])
            continue
        if state.get(name) is True:
            continue
        if name not in by_name:
            raise ModelError(f"graph refers to a node {name} that does not exist")
        if state.get(name) is False:
            raise ModelError(f"graph has a cycle through {name}")
        state[name] = False
        stack.append((name, True))
        stack.extend(
            (producer, False)
            for producer in reversed(by_name[name].inputs)
            if state.get(producer) is not True
        )
    return ordered


def _finish_output(
    builder: GraphBuilder, tf_name: str, output_name: str, box_scale: Sequence[float] | None
) -> onnx.ValueInfoProto:
    value = builder.value(tf_name)
    source = builder.in_layout(value, Layout.NATIVE)
    if box_scale is None:
        builder.emit("Identity", [source], output_name, output=output_name)
    else:
        if len(box_scale) != 4 or value.shape[-1] < 4:
            raise ModelError(
                f"box_scale needs 4 factors and >= 4 output channels, got "
                f"{list(box_scale)} for shape {value.shape}"
            )
        factors = np.ones(value.shape[-1], dtype=np.float32)
        factors[:4] = np.asarray(box_scale, dtype=np.float32)
        scale = builder.initializer(factors, "box_scale")
        builder.emit("Mul", [source, scale], output_name, output=output_name)
    return builder.value_info(output_name, value.shape)
