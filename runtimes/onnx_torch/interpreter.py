"""An ONNX graph as a ``torch.nn.Module``: our own small interpreter, no converter package.

The module is built for one static input shape, in one pass over the (topologically sorted)
nodes:

* initializers and ``Constant`` nodes are constants; so is any node whose inputs are all
  constants, and ``Shape``/``Size`` of anything, since every shape is known. Those nodes are
  evaluated once, on the CPU, and disappear: the shape arithmetic of an Ultralytics export
  (Shape, Gather, Range, Expand... building the anchor grid) folds into a few buffers.
* every other node becomes a step of the forward pass. Its inputs are the outputs of earlier
  steps, constants registered as buffers (so ``.to(device, dtype)`` moves and casts them), or
  build-time Python values for shape-like inputs (each op's ``OpDef.params`` says which).
  Shapes are propagated with ``meta`` tensors, which cost no memory and no arithmetic.

Floating tensors run in the module's precision (:meth:`OnnxModule.set_precision`), whatever
float type the file declares; integer tensors keep their type.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import torch
from google.protobuf.message import (  # type: ignore[import-untyped]  # no stubs pinned
    DecodeError as ProtobufDecodeError,
)
from onnx import helper, numpy_helper
from torch import Tensor, nn

from common.errors import ModelError, one_line
from runtimes.onnx_torch.spatial_ops import SPATIAL_OPS
from runtimes.onnx_torch.tensor_ops import (
    SHAPE_ONLY,
    TENSOR_OPS,
    Attrs,
    OpDef,
    OpFn,
    RunContext,
    onnx_dtype,
)

#: ONNX op type -> its torch function; an op not here is a ModelError naming it.
OPS: dict[str, OpDef] = {**TENSOR_OPS, **SPATIAL_OPS}

_LIVE, _BUFFER, _VALUE = 0, 1, 2  # where a step's argument comes from
_ONNX_DOMAINS = ("", "ai.onnx")
_BUILD_ERRORS = (RuntimeError, ValueError, IndexError, TypeError, KeyError)


@dataclass(frozen=True, slots=True)
class _Step:
    fn: OpFn
    args: tuple[tuple[int, Any], ...]  # (_LIVE, name) | (_BUFFER, buffer name) | (_VALUE, v)
    attrs: Attrs
    outputs: tuple[str, ...]  # "" for an output the model does not use
    frees: tuple[str, ...]  # live values read for the last time by this step


class OnnxModule(nn.Module):
    """The forward pass of an ONNX graph for one static input shape.

    ``forward(*inputs)`` takes the graph's inputs in order and returns its outputs as a list.
    """

    def __init__(
        self,
        steps: list[_Step],
        buffers: dict[str, Tensor],
        inputs: Sequence[tuple[str, tuple[int, ...]]],
        outputs: Sequence[tuple[int, str, tuple[int, ...]]],
    ) -> None:
        super().__init__()
        for name, value in buffers.items():
            self.register_buffer(name, value)
        self._steps = steps
        self._outputs = [(kind, name) for kind, name, _ in outputs]
        self.ctx = RunContext()
        self.input_names: tuple[str, ...] = tuple(name for name, _ in inputs)
        self.input_shapes: tuple[tuple[int, ...], ...] = tuple(shape for _, shape in inputs)
        self.output_shapes: tuple[tuple[int, ...], ...] = tuple(s for _, _, s in outputs)

    @property
    def num_steps(self) -> int:
        """Nodes left to run after constant folding."""
        return len(self._steps)

    def set_precision(self, dtype: torch.dtype) -> OnnxModule:
        """Cast the floating buffers to ``dtype`` and run every floating op in it."""
        if not dtype.is_floating_point:
            raise ValueError(f"precision must be a floating dtype, got {dtype}")
        self.to(dtype=dtype)
        self.ctx.float_dtype = dtype
        return self

    def forward(self, *inputs: Tensor) -> list[Tensor]:
        """Run the steps; each intermediate is dropped right after its last reader."""
        env: dict[str, Tensor] = dict(zip(self.input_names, inputs, strict=True))
        buffers = self._buffers
        ctx = self.ctx
        for step in self._steps:
            args = [
                env[v] if kind == _LIVE else buffers[v] if kind == _BUFFER else v
                for kind, v in step.args
            ]
            result = step.fn(ctx, args, step.attrs)
            if isinstance(result, Tensor):
                env[step.outputs[0]] = result
            else:
                env.update(zip(step.outputs, result, strict=False))
            for name in step.frees:
                del env[name]
        return [env[v] if kind == _LIVE else _present(buffers[v]) for kind, v in self._outputs]


def _present(value: Tensor | None) -> Tensor:
    assert value is not None  # buffers are registered with a tensor, never None
    return value


def read_model(model_path: Path) -> onnx.ModelProto:
    """Load an ONNX file (with any external weights); ModelError on one line if it is not."""
    if not model_path.is_file():
        raise ModelError(f"{model_path}: no such model file")
    try:
        return onnx.load(str(model_path))
    except (OSError, ValueError, ProtobufDecodeError) as exc:
        raise ModelError(f"{model_path}: not a valid ONNX model ({one_line(exc)})") from exc


def declared_shape(value: onnx.ValueInfoProto) -> tuple[int | None, ...]:
    """A graph input's or output's declared shape, ``None`` for a dynamic dimension."""
    dims = value.type.tensor_type.shape.dim
    return tuple(d.dim_value if d.HasField("dim_value") else None for d in dims)


def _tensor(proto: onnx.TensorProto) -> Tensor:
    array = np.array(numpy_helper.to_array(proto))  # a writable copy that torch may own
    tensor = torch.from_numpy(array)
    return tensor.float() if tensor.is_floating_point() else tensor


def _attrs(node: onnx.NodeProto, opset: int) -> Attrs:
    attrs: Attrs = {"_num_outputs": len(node.output), "_opset": opset}
    for attr in node.attribute:
        if attr.type in (onnx.AttributeProto.GRAPH, onnx.AttributeProto.GRAPHS):
            raise ModelError(f"{node.op_type} node {node.name!r}: subgraphs are not supported")
        value = helper.get_attribute_value(attr)
        if isinstance(value, bytes):
            value = value.decode()
        elif isinstance(value, onnx.TensorProto):
            value = _tensor(value)
        elif isinstance(value, list):
            value = [v.decode() if isinstance(v, bytes) else v for v in value]
        attrs[attr.name] = value
    return attrs


def _param(value: Tensor) -> Any:
    """A constant read as a build-time Python value: a list, or a scalar for a 0-d tensor."""
    return value.tolist()


def _call(op: OpDef, node: onnx.NodeProto, args: list[Any], attrs: Attrs) -> list[Tensor]:
    try:
        result = op.fn(RunContext(), args, attrs)
    except _BUILD_ERRORS as exc:
        raise ModelError(f"{node.op_type} node {node.name!r}: {one_line(exc)}") from exc
    return [result] if isinstance(result, Tensor) else list(result)


class _Builder:
    """One pass over the graph: fold what is constant, record the rest as steps."""

    def __init__(self, model: onnx.ModelProto) -> None:
        self.graph = model.graph
        self.opset = next((o.version for o in model.opset_import if o.domain in _ONNX_DOMAINS), 1)
        if self.graph.sparse_initializer:
            raise ModelError("sparse initializers are not supported")
        self.consts: dict[str, Tensor] = {i.name: _tensor(i) for i in self.graph.initializer}
        self.live: dict[str, Tensor] = {}  # meta tensors: shapes and dtypes only
        self.buffers: dict[str, Tensor] = {}  # buffer name -> constant
        self.buffer_of: dict[str, str] = {}  # constant's ONNX name -> buffer name
        self.steps: list[tuple[OpDef, onnx.NodeProto, list[tuple[int, Any]], Attrs]] = []

    def _buffer(self, name: str) -> str:
        if name not in self.buffer_of:
            self.buffer_of[name] = f"c{len(self.buffers)}"
            # A fresh dense copy: a folded constant may be a view (an Expand, a slice of a
            # larger array) that would otherwise pin its whole source or stay overlapping.
            value = self.consts[name].clone(memory_format=torch.contiguous_format)
            self.buffers[self.buffer_of[name]] = value
        return self.buffer_of[name]

    def _node(self, node: onnx.NodeProto) -> None:
        op = OPS.get(node.op_type) if node.domain in _ONNX_DOMAINS else None
        if op is None:
            domain = f"{node.domain}." if node.domain not in _ONNX_DOMAINS else ""
            raise ModelError(
                f"unsupported ONNX op {domain}{node.op_type} (node {node.name!r}); "
                "the cuda backend cannot run this model"
            )
        attrs = _attrs(node, self.opset)
        for name in node.input:
            if name and name not in self.consts and name not in self.live:
                raise ModelError(f"node {node.name!r} reads {name!r}, which nothing produces")
        if node.op_type in SHAPE_ONLY or all(not n or n in self.consts for n in node.input):
            args = [
                None
                if not n
                else _param(self.consts[n])
                if i in op.params
                else self.consts.get(n, self.live.get(n))
                for i, n in enumerate(node.input)
            ]
            self.consts.update(_named(node.output, _call(op, node, args, attrs)))
            return
        refs: list[tuple[int, Any]] = []
        for i, name in enumerate(node.input):
            if not name:
                refs.append((_VALUE, None))
            elif i in op.params:
                if name not in self.consts:
                    raise ModelError(
                        f"{node.op_type} node {node.name!r}: input {name!r} must be constant "
                        "once the input shape is fixed, but it depends on the image"
                    )
                refs.append((_VALUE, _param(self.consts[name])))
            elif name in self.consts:
                refs.append((_BUFFER, self._buffer(name)))
            else:
                refs.append((_LIVE, name))
        meta = [
            self.live[v] if kind == _LIVE else self.buffers[v].to("meta") if kind == _BUFFER else v
            for kind, v in refs
        ]
        self.live.update(_named(node.output, _call(op, node, meta, attrs)))
        self.steps.append((op, node, refs, attrs))

    def build(self, input_shapes: Sequence[Sequence[int]] | None) -> OnnxModule:
        inputs = [i for i in self.graph.input if i.name not in self.consts]
        shapes = _input_shapes(inputs, input_shapes)
        for value, shape in zip(inputs, shapes, strict=True):
            dtype = onnx_dtype(value.type.tensor_type.elem_type, RunContext())
            self.live[value.name] = torch.empty(shape, dtype=dtype, device="meta")
        with torch.no_grad():
            for node in self.graph.node:
                self._node(node)
        outputs: list[tuple[int, str, tuple[int, ...]]] = []
        for out in self.graph.output:
            if out.name in self.live:
                outputs.append((_LIVE, out.name, tuple(self.live[out.name].shape)))
            elif out.name in self.consts:
                outputs.append(
                    (_BUFFER, self._buffer(out.name), tuple(self.consts[out.name].shape))
                )
            else:
                raise ModelError(f"graph output {out.name!r} is produced by no node")
        keep = {out.name for out in self.graph.output}
        return OnnxModule(
            _with_frees(self.steps, keep),
            self.buffers,
            [(v.name, s) for v, s in zip(inputs, shapes, strict=True)],
            outputs,
        )


def _named(names: Sequence[str], values: list[Tensor]) -> dict[str, Tensor]:
    return {n: v for n, v in zip(names, values, strict=False) if n}


def _input_shapes(
    inputs: Sequence[onnx.ValueInfoProto], given: Sequence[Sequence[int]] | None
) -> list[tuple[int, ...]]:
    if given is not None:
        if len(given) != len(inputs):
            raise ModelError(f"{len(given)} input shapes given; the model has {len(inputs)} inputs")
        return [tuple(int(d) for d in s) for s in given]
    shapes = []
    for value in inputs:
        declared = declared_shape(value)
        if None in declared:
            shown = ["?" if d is None else d for d in declared]
            raise ModelError(f"input {value.name!r} has a dynamic shape {shown}; give a static one")
        shapes.append(tuple(d for d in declared if d is not None))
    return shapes


def _with_frees(
    steps: list[tuple[OpDef, onnx.NodeProto, list[tuple[int, Any]], Attrs]], keep: set[str]
) -> list[_Step]:
    """Steps that also say which live values die after them, to keep peak memory low."""
    last_use: dict[str, int] = {}
    for index, (_, node, refs, _) in enumerate(steps):
        for name in node.output:
            last_use.setdefault(name, index)  # an output nobody reads dies at once
        for kind, value in refs:
            if kind == _LIVE:
                last_use[value] = index
    dying: dict[int, list[str]] = {}
    for name, index in last_use.items():
        if name and name not in keep:
            dying.setdefault(index, []).append(name)
    return [
        _Step(
            fn=op.fn,
            args=tuple(refs),
            attrs=attrs,
            outputs=tuple(node.output),
            frees=tuple(dying.get(index, ())),
        )
        for index, (op, node, refs, attrs) in enumerate(steps)
    ]


def build_module(
    model: onnx.ModelProto, input_shapes: Sequence[Sequence[int]] | None = None
) -> OnnxModule:
    """Build the forward pass of ``model`` for static ``input_shapes`` (default: as declared).

    Raises ModelError naming the first unsupported op, or the node that cannot be built.
    The module is fp32 on the CPU; move it with ``.to(device)`` and ``set_precision``.
    """
    return _Builder(model).build(input_shapes)


def load_module(
    model_path: Path, input_shapes: Sequence[Sequence[int]] | None = None
) -> OnnxModule:
    """:func:`read_model` then :func:`build_module`."""
    return build_module(read_model(model_path), input_shapes)
