"""One translator per TF.js op: each emits the ONNX nodes of one TF.js node (see tfjs_to_onnx).

A translator reads its node's inputs from the :class:`GraphBuilder`, in whatever layout they
are kept, emits ONNX nodes, and defines the node's output with its NHWC shape and layout.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from common.errors import ModelError
from modelprep.acquire.tfjs_graph import TfNode, strided_slice_plan
from modelprep.acquire.tfjs_onnx_builder import (
    NHWC_TO_NCHW,
    GraphBuilder,
    Layout,
    pick_layout,
)

Translator = Callable[[GraphBuilder, TfNode], None]
_FUSED_ACTIVATIONS = {"Relu": "Relu", "Elu": "Elu"}  # TF fused_ops name -> ONNX op (same maths)


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
    elif builder.dynamic_batch:  # sizes: the input's own batch and channels, then out_h, out_w
        nchw = builder.in_layout(x, Layout.NCHW)
        batch_channels = builder.emit("Shape", [nchw], f"{node.name}/shape", start=0, end=2)
        spatial = builder.initializer(np.array([out_h, out_w], np.int64), "sizes")
        sizes_name = builder.emit("Concat", [batch_channels, spatial], f"{node.name}/sizes", axis=0)
        size_inputs = ["", "", sizes_name]
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
    shape = builder.reshape_target(x.shape, target)
    out = builder.emit("Reshape", [builder.in_layout(x, Layout.NATIVE), shape], node.name)
    builder.define(node.name, out, tuple(target), Layout.NATIVE)


def _transpose(builder: GraphBuilder, node: TfNode) -> None:
    x = builder.value(node.inputs[0])
    perm = [int(v) for v in builder.constant(node, 1)]
    if builder.dynamic_batch and perm and perm[0] != 0:
        raise ModelError(f"Transpose {node.name} moves the batch axis (perm {perm})")
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
    if builder.dynamic_batch and x.shape:
        # Batch-independent only if a batch of 2 slices the same axes and keeps axis 0.
        twice = strided_slice_plan((2, *x.shape[1:]), begin, end, strides, **masks)
        if twice.axes != plan.axes or twice.out_shape != (2, *plan.out_shape[1:]):
            raise ModelError(f"StridedSlice {node.name} slices the batch axis")
    out = builder.in_layout(x, Layout.NATIVE)
    if plan.axes:
        inputs = [np.array(v, np.int64) for v in (plan.starts, plan.ends, plan.axes, plan.steps)]
        out = builder.emit(
            "Slice", [out, *(builder.initializer(v, "slice") for v in inputs)], node.name
        )
    if plan.needs_reshape:
        shape = builder.reshape_target(plan.sliced_shape, plan.out_shape)
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


#: TF.js op -> its translator; an op not here is a ModelError naming it.
TRANSLATORS: dict[str, Translator] = {
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
