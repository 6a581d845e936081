"""The ONNX operators our interpreter knows, each a small function over torch tensors.

Every entry of :data:`TENSOR_OPS` (and of ``spatial_ops.SPATIAL_OPS``) is
``op_type -> OpDef(fn, params)``. ``fn(ctx, args, attrs)`` gets the node's inputs in order:
tensors for data inputs, ``None`` for an omitted optional input, and, for the input indices in
``params`` (shapes, axes, pads, scales...), plain Python values read once when the module is
built. Keeping those off the tensor path is what lets a forward pass run without a single
GPU-to-host read, which CUDA graph capture needs.

Semantics follow the ONNX operator docs for opset 13 and later (older attribute forms of
Slice, Split, Squeeze, Unsqueeze, Clip and the reductions are read too). Where an ONNX mode has
no exact torch counterpart (some Resize modes) the function raises ModelError rather than run
something close.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F
from onnx import TensorProto
from torch import Tensor

from common.errors import ModelError

Attrs = dict[str, Any]


@dataclass(slots=True)
class RunContext:
    """What ops need beyond their inputs: the dtype floating tensors run in (fp32 or fp16)."""

    float_dtype: torch.dtype = torch.float32


OpResult = Tensor | tuple[Tensor, ...]
OpFn = Callable[[RunContext, list[Any], Attrs], OpResult]


@dataclass(frozen=True, slots=True)
class OpDef:
    """An op's function and the input indices it reads as build-time Python values."""

    fn: OpFn
    params: frozenset[int] = frozenset()


_DTYPES: dict[int, torch.dtype] = {
    TensorProto.UINT8: torch.uint8,
    TensorProto.INT8: torch.int8,
    TensorProto.INT16: torch.int16,
    TensorProto.INT32: torch.int32,
    TensorProto.INT64: torch.int64,
    TensorProto.BOOL: torch.bool,
}
_FLOATS = {TensorProto.FLOAT, TensorProto.FLOAT16, TensorProto.DOUBLE, TensorProto.BFLOAT16}


def onnx_dtype(elem_type: int, ctx: RunContext) -> torch.dtype:
    """The torch dtype for an ONNX element type; every float type runs in ``ctx.float_dtype``."""
    if elem_type in _FLOATS:
        return ctx.float_dtype
    if elem_type not in _DTYPES:
        raise ModelError(f"ONNX element type {elem_type} is not supported")
    return _DTYPES[elem_type]


def arg(args: list[Any], index: int) -> Any:
    """Input ``index``, or None when the node omits it."""
    return args[index] if index < len(args) else None


def ints(args: list[Any], index: int, attrs: Attrs, name: str) -> list[int] | None:
    """A list of ints from input ``index`` (opset 13+) or, in older opsets, attribute ``name``."""
    value = arg(args, index)
    if value is None:
        value = attrs.get(name)
    if value is None:
        return None
    return [int(v) for v in (value if isinstance(value, list) else [value])]


# --- element-wise -------------------------------------------------------------------------


def _unary(fn: Callable[[Tensor], Tensor]) -> OpDef:
    return OpDef(lambda ctx, x, a: fn(x[0]))


def _binary(fn: Callable[[Tensor, Tensor], Tensor]) -> OpDef:
    return OpDef(lambda ctx, x, a: fn(x[0], x[1]))


def _variadic(fn: Callable[[Tensor, Tensor], Tensor]) -> OpDef:
    def run(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
        out: Tensor = x[0]
        for t in x[1:]:
            out = fn(out, t)
        return out

    return OpDef(run)


def _div(a: Tensor, b: Tensor) -> Tensor:
    # ONNX integer division truncates toward zero, as C does.
    if a.is_floating_point():
        return a / b
    return torch.div(a, b, rounding_mode="trunc")


def _clip(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    low, high = arg(x, 1), arg(x, 2)
    low = a.get("min") if low is None else low
    high = a.get("max") if high is None else high
    return torch.clamp(x[0], min=low, max=high)


def _cast(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    return data.to(onnx_dtype(int(a["to"]), ctx))


def _where(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    return torch.where(x[0], x[1], x[2])


# --- shapes and indexing ------------------------------------------------------------------


def _shape(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    dims = list(x[0].shape)[a.get("start", 0) : a.get("end", None)]
    return torch.tensor(dims, dtype=torch.int64)


def _constant(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    for key in ("value", "value_float", "value_floats", "value_int", "value_ints"):
        if key in a:
            value = a[key]
            if isinstance(value, Tensor):
                return value
            dtype = torch.int64 if "int" in key else torch.float32
            return torch.tensor(value, dtype=dtype)
    raise ModelError(f"Constant node without a supported value attribute ({sorted(a)})")


def _constant_of_shape(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    value = a.get("value")
    fill = torch.zeros(1, dtype=torch.float32) if value is None else value.reshape(-1)
    dtype = ctx.float_dtype if fill.is_floating_point() else fill.dtype
    return torch.full([int(d) for d in x[0]], fill[0].item(), dtype=dtype)


def _range(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    start, limit, delta = (t.item() for t in x[:3])
    return torch.arange(start, limit, delta, dtype=x[0].dtype)


def _reshape(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    shape = [int(d) for d in x[1]]
    if not a.get("allowzero", 0):  # 0 means "keep this input dimension"
        shape = [data.shape[i] if d == 0 else d for i, d in enumerate(shape)]
    return data.reshape(shape)


def _flatten(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    axis = a.get("axis", 1) % (data.dim() + 1) if data.dim() else 0
    return data.reshape(math.prod(data.shape[:axis]), math.prod(data.shape[axis:]))


def _transpose(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    perm = a.get("perm") or list(reversed(range(data.dim())))
    return data.permute(perm)


def _unsqueeze(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    axes = ints(x, 1, a, "axes") or []
    rank = data.dim() + len(axes)
    for axis in sorted(ax % rank for ax in axes):
        data = data.unsqueeze(axis)
    return data


def _squeeze(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    axes = ints(x, 1, a, "axes")
    if axes is None:
        return data.squeeze()
    for axis in sorted((ax % data.dim() for ax in axes), reverse=True):
        data = data.squeeze(axis)
    return data


def _expand(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    # ONNX broadcasts both ways (the shape may hold 1s where the data does not, or fewer
    # axes); torch's expand only grows the data, so compute the broadcast shape first.
    data: Tensor = x[0]
    shape = [int(d) for d in x[1]]
    rank = max(data.dim(), len(shape))
    left = [1] * (rank - data.dim()) + list(data.shape)
    right = [1] * (rank - len(shape)) + shape
    return data.expand([max(m, n) if 1 in (m, n) else m for m, n in zip(left, right, strict=True)])


def _concat(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    return torch.cat(x, dim=int(a["axis"]))


def _split(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    axis = a.get("axis", 0)
    sizes = ints(x, 1, a, "split")
    if sizes is None:
        parts = int(a["num_outputs"] if "num_outputs" in a else a["_num_outputs"])
        chunk = math.ceil(data.shape[axis] / parts)
        return tuple(torch.split(data, chunk, dim=axis))
    return tuple(torch.split(data, sizes, dim=axis))


def _slice(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    starts = ints(x, 1, a, "starts") or []
    ends = ints(x, 2, a, "ends") or []
    axes = ints(x, 3, a, "axes") or list(range(len(starts)))
    steps = ints(x, 4, a, "steps") or [1] * len(starts)
    for start, end, axis, step in zip(starts, ends, axes, steps, strict=True):
        axis %= data.dim()
        n = data.shape[axis]
        start += n if start < 0 else 0
        end += n if end < 0 else 0
        lead = (slice(None),) * axis
        if step > 0:
            data = data[(*lead, slice(max(0, min(start, n)), max(0, min(end, n)), step))]
        else:  # torch slices forward only: walk the flipped axis instead
            start, end = max(0, min(start, n - 1)), max(-1, min(end, n - 1))
            data = data.flip(axis)[(*lead, slice(n - 1 - start, n - 1 - end, -step))]
    return data


def _gather(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    indices: Tensor = x[1].to(torch.int64)
    axis = a.get("axis", 0) % data.dim()
    n = data.shape[axis]
    indices = torch.where(indices < 0, indices + n, indices)
    picked = data.index_select(axis, indices.reshape(-1))
    return picked.reshape((*data.shape[:axis], *indices.shape, *data.shape[axis + 1 :]))


# --- reductions and normalisation ---------------------------------------------------------


def _reduce(fn: Callable[[Tensor, list[int], bool], Tensor]) -> OpDef:
    def run(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
        data: Tensor = x[0]
        axes = ints(x, 1, a, "axes")
        if axes is None or not axes:
            if a.get("noop_with_empty_axes", 0):
                return data
            axes = list(range(data.dim()))
        return fn(data, [ax % data.dim() for ax in axes], bool(a.get("keepdims", 1)))

    return OpDef(run, frozenset({1}))


def _softmax(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    if a["_opset"] >= 13:
        return torch.softmax(data, dim=a.get("axis", -1))
    # Before opset 13 the input is seen as 2-D, flattened at ``axis`` (default 1).
    axis = a.get("axis", 1) % data.dim()
    flat = data.reshape(math.prod(data.shape[:axis]), -1)
    return torch.softmax(flat, dim=1).reshape(data.shape)


def _argmax(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    if a.get("select_last_index", 0):
        raise ModelError("ArgMax with select_last_index=1 is not supported")
    return torch.argmax(x[0], dim=a.get("axis", 0), keepdim=bool(a.get("keepdims", 1)))


def _batch_norm(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    if a["_num_outputs"] > 1:
        raise ModelError("BatchNormalization in training mode is not supported")
    data, scale, bias, mean, var = x[:5]
    return F.batch_norm(data, mean, var, scale, bias, False, 0.0, a.get("epsilon", 1e-5))


# --- linear algebra -------------------------------------------------------------------------


def _gemm(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    left: Tensor = x[0].t() if a.get("transA", 0) else x[0]
    right: Tensor = x[1].t() if a.get("transB", 0) else x[1]
    out: Tensor = float(a.get("alpha", 1.0)) * (left @ right)
    bias: Tensor | None = arg(x, 2)
    return out if bias is None else out + float(a.get("beta", 1.0)) * bias


#: The element-wise, shape, indexing and reduction ops (spatial_ops has the rest).
TENSOR_OPS: dict[str, OpDef] = {
    "Abs": _unary(torch.abs),
    "Add": _binary(torch.add),
    "And": _binary(torch.logical_and),
    "ArgMax": OpDef(_argmax),
    "BatchNormalization": OpDef(_batch_norm),
    "Cast": OpDef(_cast),
    "Ceil": _unary(torch.ceil),
    "Clip": OpDef(_clip, frozenset({1, 2})),
    "Concat": OpDef(_concat),
    "Constant": OpDef(_constant),
    "ConstantOfShape": OpDef(_constant_of_shape, frozenset({0})),
    "Div": _binary(_div),
    "Equal": _binary(torch.eq),
    "Erf": _unary(torch.erf),
    "Exp": _unary(torch.exp),
    "Expand": OpDef(_expand, frozenset({1})),
    "Flatten": OpDef(_flatten),
    "Floor": _unary(torch.floor),
    "Gather": OpDef(_gather),
    "Gemm": OpDef(_gemm),
    "GlobalAveragePool": _unary(lambda t: t.mean(dim=tuple(range(2, t.dim())), keepdim=True)),
    "GlobalMaxPool": _unary(lambda t: t.amax(dim=tuple(range(2, t.dim())), keepdim=True)),
    "Greater": _binary(torch.gt),
    "HardSigmoid": OpDef(
        lambda ctx, x, a: torch.clamp(a.get("alpha", 0.2) * x[0] + a.get("beta", 0.5), 0, 1)
    ),
    "HardSwish": _unary(F.hardswish),
    "Identity": _unary(lambda t: t),
    "LeakyRelu": OpDef(lambda ctx, x, a: F.leaky_relu(x[0], a.get("alpha", 0.01))),
    "Less": _binary(torch.lt),
    "Log": _unary(torch.log),
    "MatMul": _binary(torch.matmul),
    "Max": _variadic(torch.maximum),
    "Min": _variadic(torch.minimum),
    "Mul": _binary(torch.mul),
    "Neg": _unary(torch.neg),
    "Not": _unary(torch.logical_not),
    "Pow": _binary(torch.pow),
    "Range": OpDef(_range),
    "Reciprocal": _unary(torch.reciprocal),
    "ReduceMax": _reduce(lambda t, dims, keep: t.amax(dim=dims, keepdim=keep)),
    "ReduceMean": _reduce(lambda t, dims, keep: t.mean(dim=dims, keepdim=keep)),
    "ReduceMin": _reduce(lambda t, dims, keep: t.amin(dim=dims, keepdim=keep)),
    "ReduceSum": _reduce(lambda t, dims, keep: t.sum(dim=dims, keepdim=keep)),
    "Relu": _unary(torch.relu),
    "Reshape": OpDef(_reshape, frozenset({1})),
    "Shape": OpDef(_shape),
    "Sigmoid": _unary(torch.sigmoid),
    "Size": OpDef(lambda ctx, x, a: torch.tensor(x[0].numel(), dtype=torch.int64)),
    "Slice": OpDef(_slice, frozenset({1, 2, 3, 4})),
    "Softmax": OpDef(_softmax),
    "Split": OpDef(_split, frozenset({1})),
    "Sqrt": _unary(torch.sqrt),
    "Squeeze": OpDef(_squeeze, frozenset({1})),
    "Sub": _binary(torch.sub),
    "Tanh": _unary(torch.tanh),
    "Transpose": OpDef(_transpose),
    "Unsqueeze": OpDef(_unsqueeze, frozenset({1})),
    "Where": OpDef(_where),
}

#: Ops that read only their input's shape, so they fold even when that input is live.
SHAPE_ONLY = frozenset({"Shape", "Size"})
