"""Translate a TF.js graph model into an ONNX model that ONNX Runtime and TensorRT run well.

Layout: TensorFlow computes in NHWC, ONNX Conv/MaxPool/Resize in NCHW. Wrapping every conv in
a pair of Transposes would work but costs copies, so instead each translated tensor carries a
layout tag. A 4-D feature map is kept in NCHW (``Layout.NCHW``) while its *shape* is still
recorded in TF's NHWC terms; axis-dependent ops (Concat, Pad, Resize, constants broadcast in
elementwise ops) remap their axes. Ops whose meaning depends on the memory order (Reshape,
Transpose, StridedSlice) get a ``Layout.NATIVE`` input, converted by one cached Transpose. For
YOLOv5 that adds just one Transpose per detection head, before its Reshape.

Scope: single-input, single-output graphs with static shapes, float32 data; the op table below
covers what the TF.js converter emits for YOLOv5. Anything else raises ModelError naming the op.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import onnx
from onnx import TensorProto, helper

from common.errors import ModelError
from services.detector.acquire.tfjs_graph import (
    TfGraph,
    TfNode,
    load_tfjs_graph,
    strided_slice_plan,
)
from services.detector.acquire.tfjs_onnx_builder import (
    NHWC_TO_NCHW,
    GraphBuilder,
    Layout,
    pick_layout,
)

OPSET = 17  # Resize-13 semantics, and parsed by TensorRT 8.6+/10
IR_VERSION = 8  # the IR that opset 17 shipped with; older runtimes reject newer IRs

Translator = Callable[[GraphBuilder, TfNode], None]
_FUSED_ACTIVATIONS = {"Relu": "Relu", "Elu": "Elu"}  # TF fused_ops name -> ONNX op (same maths)


def convert_tfjs_to_onnx(
    model_json: Path,
    out_path: Path,
    *,
    names: Sequence[str],
    metadata: Mapping[str, str],
    box_scale: Sequence[float] | None = None,
) -> None:
    """Convert ``model_json`` (+ shards) into ``out_path``; see convert_tfjs_graph."""
    convert_tfjs_graph(
        load_tfjs_graph(model_json), out_path, names=names, metadata=metadata, box_scale=box_scale
    )


def convert_tfjs_graph(
    graph: TfGraph,
    out_path: Path,
    *,
    names: Sequence[str],
    metadata: Mapping[str, str],
    box_scale: Sequence[float] | None = None,
    input_name: str = "images",
    output_name: str = "output0",
) -> None:
    """Write the ONNX translation of ``graph``.

    ``names`` becomes the Ultralytics-style ``names`` metadata ("{0: 'person', ...}").
    ``box_scale`` (4 factors) multiplies channels 0..3 of the output's last axis, turning the
    TF.js normalised cx, cy, w, h into input pixels like Ultralytics' own ONNX export.
    """
    model = build_onnx_model(
        graph,
        names=names,
        metadata=metadata,
        box_scale=box_scale,
        input_name=input_name,
        output_name=output_name,
    )
    try:
        onnx.save(model, str(out_path))
    except OSError as exc:
        raise ModelError(f"cannot write {out_path}: {exc.strerror or exc}") from exc


def build_onnx_model(
    graph: TfGraph,
    *,
    names: Sequence[str],
    metadata: Mapping[str, str],
    box_scale: Sequence[float] | None = None,
    input_name: str = "images",
    output_name: str = "output0",
) -> onnx.ModelProto:
    """Translate ``graph`` into a checked in-memory ONNX model."""
    if len(graph.inputs) != 1 or len(graph.outputs) != 1:
        raise ModelError(
            f"expected one input and one output, got {list(graph.inputs)} and {list(graph.outputs)}"
        )
    builder = GraphBuilder(graph.constants)
    ((tf_input, shape),) = graph.inputs.items()
    graph_input = builder.define_input(tf_input, input_name, shape)
    for node in _reachable_nodes(graph):
        translator = _TRANSLATORS.get(node.op)
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
        producer_name="services.detector.acquire.tfjs_to_onnx",
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
    return helper.make_tensor_value_info(output_name, TensorProto.FLOAT, list(value.shape))


# ---------------------------------------------------------------- op translators


def _ignore(builder: GraphBuilder, node: TfNode) -> None:
    """Const and Placeholder: constants become initializers when used, the input is defined."""


def _identity(builder: GraphBuilder, node: TfNode) -> None:
    builder.alias(node.name, node.inputs[0])


def _fused_conv2d(builder: GraphBuilder, node: TfNode) -> None:
    _expect(node, "data_format", ("NHWC", None))
    fused = node.attr_strs("fused_ops")
    if fused[:1] != ("BiasAdd",) or len(fused) > 2 or not set(fused[1:]) <= set(_FUSED_ACTIVATIONS):
        raise ModelError(f"unsupported _FusedConv2D fused_ops {list(fused)} (node {node.name})")
    x = builder.value(node.inputs[0])
    kernel = builder.constant(node, 1)  # HWIO
    bias = builder.constant(node, 2)
    kh, kw, cin_per_group, cout = kernel.shape
    strides, dilations = _hw_attr(node, "strides"), _hw_attr(node, "dilations")
    padding = str(node.attrs.get("padding"))
    pads, out_hw = _spatial_pads(node, x.shape[1:3], (kh, kw), strides, dilations, padding)
    if x.shape[3] % cin_per_group:
        raise ModelError(f"conv {node.name}: {x.shape[3]} input channels, kernel {kernel.shape}")
    weight = builder.initializer(kernel.transpose(3, 2, 0, 1), f"{node.name}/weight")  # OIHW
    out = builder.emit(
        "Conv",
        [builder.in_layout(x, Layout.NCHW), weight, builder.initializer(bias, f"{node.name}/bias")],
        node.name,
        kernel_shape=[kh, kw],
        strides=list(strides),
        dilations=list(dilations),
        pads=pads,
        group=x.shape[3] // cin_per_group,
    )
    if len(fused) == 2:
        out = builder.emit(_FUSED_ACTIVATIONS[fused[1]], [out], f"{node.name}/{fused[1]}")
    builder.define(node.name, out, (x.shape[0], *out_hw, cout), Layout.NCHW)


def _max_pool(builder: GraphBuilder, node: TfNode) -> None:
    _expect(node, "data_format", ("NHWC", None))
    x = builder.value(node.inputs[0])
    kernel, strides = _hw_attr(node, "ksize"), _hw_attr(node, "strides")
    pads, out_hw = _spatial_pads(
        node, x.shape[1:3], kernel, strides, (1, 1), str(node.attrs.get("padding"))
    )
    out = builder.emit(
        "MaxPool",
        [builder.in_layout(x, Layout.NCHW)],
        node.name,
        kernel_shape=list(kernel),
        strides=list(strides),
        pads=pads,
    )
    builder.define(node.name, out, (x.shape[0], *out_hw, x.shape[3]), Layout.NCHW)


def _pad(builder: GraphBuilder, node: TfNode) -> None:
    x = builder.value(node.inputs[0])
    paddings = builder.constant(node, 1).astype(np.int64).reshape(len(x.shape), 2)
    shape = tuple(int(d + b + a) for d, (b, a) in zip(x.shape, paddings, strict=True))
    if x.layout is Layout.NCHW:
        paddings = paddings[list(NHWC_TO_NCHW)]
    pads = builder.initializer(np.concatenate([paddings[:, 0], paddings[:, 1]]), "pads")
    out = builder.emit("Pad", [x.name, pads], node.name, mode="constant")
    builder.define(node.name, out, shape, x.layout)


def _concat(builder: GraphBuilder, node: TfNode) -> None:
    axis_index = len(node.inputs) - 1
    parts = node.inputs[:axis_index]
    layout = pick_layout(builder, parts)
    shapes = [builder.shape_of(name) for name in parts]
    rank = len(shapes[0])
    axis = int(builder.constant(node, axis_index)) % rank
    shape = list(shapes[0])
    shape[axis] = sum(s[axis] for s in shapes)
    onnx_axis = NHWC_TO_NCHW.index(axis) if layout is Layout.NCHW else axis
    out = builder.emit(
        "Concat", [builder.operand(name, layout) for name in parts], node.name, axis=onnx_axis
    )
    builder.define(node.name, out, tuple(shape), layout)


def _resize_nearest(builder: GraphBuilder, node: TfNode) -> None:
    x = builder.value(node.inputs[0])
    out_h, out_w = (int(v) for v in builder.constant(node, 1))
    scale_h, scale_w = out_h / x.shape[1], out_w / x.shape[2]
    if node.attrs.get("align_corners"):
        mode, rounding = "align_corners", "round_prefer_ceil"
    elif node.attrs.get("half_pixel_centers") and not (
        scale_h.is_integer() and scale_w.is_integer()
    ):
        mode, rounding = "half_pixel", "round_prefer_ceil"  # == TF floor((i + 0.5) / scale)
    else:
        # For an integer upscale, TF's half-pixel floor((i + .5) / s) equals floor(i / s).
        mode, rounding = "asymmetric", "floor"
    if scale_h.is_integer() and scale_w.is_integer():
        scales = np.array([1, 1, scale_h, scale_w], np.float32)
        size_inputs = ["", builder.initializer(scales, "scales")]
    else:  # float scales could round the output size down (5 * 9/5 -> 8.999)
        sizes = np.array([x.shape[0], x.shape[3], out_h, out_w], np.int64)
        size_inputs = ["", "", builder.initializer(sizes, "sizes")]
    out = builder.emit(
        "Resize",
        [builder.in_layout(x, Layout.NCHW), *size_inputs],
        node.name,
        mode="nearest",
        coordinate_transformation_mode=mode,
        nearest_mode=rounding,
    )
    builder.define(node.name, out, (x.shape[0], out_h, out_w, x.shape[3]), Layout.NCHW)


def _reshape(builder: GraphBuilder, node: TfNode) -> None:
    x = builder.value(node.inputs[0])
    target = [int(v) for v in builder.constant(node, 1)]
    total = int(np.prod(x.shape))
    known = int(np.prod([d for d in target if d != -1]))
    if target.count(-1) == 1 and known and total % known == 0:
        target[target.index(-1)] = total // known
    if int(np.prod(target)) != total or min(target) < 0:
        raise ModelError(f"cannot reshape {x.shape} to {target} (node {node.name})")
    shape = builder.initializer(np.array(target, np.int64), "shape")
    out = builder.emit("Reshape", [builder.in_layout(x, Layout.NATIVE), shape], node.name)
    builder.define(node.name, out, tuple(target), Layout.NATIVE)


def _transpose(builder: GraphBuilder, node: TfNode) -> None:
    x = builder.value(node.inputs[0])
    perm = [int(v) for v in builder.constant(node, 1)]
    out = builder.emit("Transpose", [builder.in_layout(x, Layout.NATIVE)], node.name, perm=perm)
    builder.define(node.name, out, tuple(x.shape[p] for p in perm), Layout.NATIVE)


def _strided_slice(builder: GraphBuilder, node: TfNode) -> None:
    x = builder.value(node.inputs[0])
    begin, end, strides = (builder.constant(node, i) for i in (1, 2, 3))
    masks = {
        key: node.attr_int(key)
        for key in ("begin_mask", "end_mask", "ellipsis_mask", "new_axis_mask", "shrink_axis_mask")
    }
    plan = strided_slice_plan(x.shape, begin, end, strides, **masks)
    out = builder.in_layout(x, Layout.NATIVE)
    if plan.axes:
        inputs = [np.array(v, np.int64) for v in (plan.starts, plan.ends, plan.axes, plan.steps)]
        out = builder.emit(
            "Slice", [out, *(builder.initializer(v, "slice") for v in inputs)], node.name
        )
    if plan.needs_reshape:
        shape = builder.initializer(np.array(plan.out_shape, np.int64), "shape")
        out = builder.emit("Reshape", [out, shape], f"{node.name}/reshape")
    builder.define(node.name, out, plan.out_shape, Layout.NATIVE)


def _elementwise(onnx_op: str) -> Translator:
    def translate(builder: GraphBuilder, node: TfNode) -> None:
        layout = pick_layout(builder, node.inputs)
        shape = np.broadcast_shapes(*(builder.shape_of(name) for name in node.inputs))
        out = builder.emit(
            onnx_op, [builder.operand(name, layout) for name in node.inputs], node.name
        )
        builder.define(node.name, out, tuple(int(d) for d in shape), layout)

    return translate


def _square(builder: GraphBuilder, node: TfNode) -> None:
    """x * x rather than Pow: cheaper and every backend has it."""
    x = builder.value(node.inputs[0])
    out = builder.emit("Mul", [x.name, x.name], node.name)
    builder.define(node.name, out, x.shape, x.layout)


_TRANSLATORS: dict[str, Translator] = {
    "Const": _ignore,
    "Placeholder": _ignore,
    "Identity": _identity,
    "_FusedConv2D": _fused_conv2d,
    "MaxPool": _max_pool,
    "Pad": _pad,
    "ConcatV2": _concat,
    "ResizeNearestNeighbor": _resize_nearest,
    "Reshape": _reshape,
    "Transpose": _transpose,
    "StridedSlice": _strided_slice,
    "Mul": _elementwise("Mul"),
    "Add": _elementwise("Add"),
    "AddV2": _elementwise("Add"),
    "Sigmoid": _elementwise("Sigmoid"),
    "Square": _square,
}


# ---------------------------------------------------------------- attribute helpers


def _expect(node: TfNode, key: str, allowed: tuple[str | None, ...]) -> None:
    if node.attrs.get(key) not in allowed:
        raise ModelError(f"{node.op} {node.name}: unsupported {key}={node.attrs.get(key)!r}")


def _hw_attr(node: TfNode, key: str) -> tuple[int, int]:
    """The H, W entries of an NHWC 4-list attribute (strides, dilations, ksize)."""
    raw: Any = node.attrs.get(key) or (1, 1, 1, 1)
    values = tuple(int(v) for v in raw)
    if len(values) != 4 or values[0] != 1 or values[3] != 1:
        raise ModelError(f"{node.op} {node.name}: unsupported {key}={list(values)}")
    return values[1], values[2]


def _spatial_pads(
    node: TfNode,
    in_hw: Sequence[int],
    kernel: Sequence[int],
    strides: Sequence[int],
    dilations: Sequence[int],
    padding: str,
) -> tuple[list[int], tuple[int, int]]:
    """Explicit ONNX pads [h0, w0, h1, w1] and the output H, W for TF SAME/VALID padding.

    Explicit pads rather than auto_pad: TF's SAME puts the odd pixel at the end, and spelling
    it out keeps every backend from guessing.
    """
    begins, ends, out = [], [], []
    for size, k, s, d in zip(in_hw, kernel, strides, dilations, strict=True):
        span = (k - 1) * d + 1
        if padding == "SAME":
            out_size = -(-size // s)
            total = max((out_size - 1) * s + span - size, 0)
        elif padding == "VALID":
            out_size, total = (size - span) // s + 1, 0
        else:
            raise ModelError(f"{node.op} {node.name}: unsupported padding {padding!r}")
        if out_size < 1:
            raise ModelError(f"{node.op} {node.name}: input {list(in_hw)} too small")
        begins.append(total // 2)
        ends.append(total - total // 2)
        out.append(out_size)
    return begins + ends, (out[0], out[1])
