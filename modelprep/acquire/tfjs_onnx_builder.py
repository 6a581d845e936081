"""The ONNX graph under construction while translating a TF.js graph, with layout tracking.

Every translated TF tensor is a ``Value``: the ONNX tensor name, its shape in TF's own (NHWC)
terms, and the memory layout the ONNX tensor actually has. Feature maps live in NCHW so that
Conv, MaxPool and Resize run natively; ``in_layout`` inserts (and caches) the one Transpose an
op needs when it must see TF's original memory order.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import onnx
from onnx import helper, numpy_helper

from common.errors import ModelError
from modelprep.acquire.tfjs_graph import TfNode

NHWC_TO_NCHW = (0, 3, 1, 2)  # ONNX axis j of an NCHW tensor is TF (NHWC) axis NHWC_TO_NCHW[j]
NCHW_TO_NHWC = (0, 2, 3, 1)
#: The name of a dynamic batch dimension in the graph's input and output.
BATCH_DIM = "batch"
BATCH_DENOTATION = "DATA_BATCH"


class Layout(enum.Enum):
    NATIVE = "native"  # same memory order as the TF tensor
    NCHW = "nchw"  # a 4-D NHWC TF tensor stored transposed to NCHW


@dataclass(frozen=True, slots=True)
class Value:
    """A translated tensor: ``shape`` is always in TF terms, whatever the layout."""

    name: str
    shape: tuple[int, ...]
    layout: Layout

    @property
    def onnx_shape(self) -> tuple[int, ...]:
        if self.layout is Layout.NCHW:
            return tuple(self.shape[axis] for axis in NHWC_TO_NCHW)
        return self.shape


class GraphBuilder:
    """Collects ONNX nodes and initializers; maps TF node names to translated values."""

    def __init__(
        self, constants: Mapping[str, npt.NDArray[Any]], *, dynamic_batch: bool = False
    ) -> None:
        #: Whether the graph's batch (axis 0 of the input, 1 in TF's shapes) is left dynamic:
        #: shapes written into the graph then copy it from their input instead of baking it in.
        self.dynamic_batch = dynamic_batch
        self.nodes: list[onnx.NodeProto] = []
        self.initializers: list[onnx.TensorProto] = []
        self._constants = dict(constants)
        self._values: dict[str, Value] = {}
        self._relaid: dict[tuple[str, Layout], str] = {}
        self._constant_operands: dict[tuple[str, Layout], str] = {}
        self._used_names: set[str] = set()

    # ----------------------------------------------------------- names and constants

    def unique(self, hint: str) -> str:
        name, suffix = hint, 1
        while name in self._used_names:
            suffix += 1
            name = f"{hint}_{suffix}"
        self._used_names.add(name)
        return name

    def constant(self, node: TfNode, index: int) -> npt.NDArray[Any]:
        """Input ``index`` of ``node`` as a numpy array; it must be a graph constant."""
        if index >= len(node.inputs):
            raise ModelError(f"{node.op} {node.name} has no input {index}")
        array = self._constants.get(node.inputs[index])
        if array is None:
            raise ModelError(
                f"{node.op} {node.name}: input {index} ({node.inputs[index]}) must be a constant"
            )
        return array

    def initializer(self, array: npt.NDArray[Any], hint: str) -> str:
        name = self.unique(hint)
        self.initializers.append(numpy_helper.from_array(np.ascontiguousarray(array), name))
        return name

    # ----------------------------------------------------------- values

    def define_input(
        self, tf_name: str, onnx_name: str, shape: tuple[int, ...]
    ) -> onnx.ValueInfoProto:
        """The graph input: a 4-D NHWC image is exposed as NCHW, like every ONNX detector."""
        layout = Layout.NCHW if len(shape) == 4 else Layout.NATIVE
        self._used_names.add(onnx_name)
        value = Value(onnx_name, shape, layout)
        self._values[tf_name] = value
        return self.value_info(onnx_name, value.onnx_shape)

    def value_info(self, name: str, shape: Sequence[int]) -> onnx.ValueInfoProto:
        """A graph input or output of ``shape``. With a dynamic batch, axis 0 is named
        ``batch`` and denoted ``DATA_BATCH`` (ONNX's standard denotation: a runtime may pin
        it by that, as ONNX Runtime's free dimension overrides do)."""
        dims: list[int | str] = list(shape)
        if self.dynamic_batch and dims:
            dims[0] = BATCH_DIM
        info = helper.make_tensor_value_info(name, onnx.TensorProto.FLOAT, dims)
        if self.dynamic_batch and dims:
            info.type.tensor_type.shape.dim[0].denotation = BATCH_DENOTATION
        return info

    def reshape_target(self, source_shape: Sequence[int], target: Sequence[int]) -> str:
        """An initializer with a Reshape's ``target`` shape for a ``source_shape`` input. With
        a dynamic batch, a leading dimension equal to the source's is written 0 ("copy the
        input's"): the same shape for a batch of 1, and the right one for any other; a
        reshape that moves the batch axis is a ModelError then."""
        dims = np.array(target, np.int64)
        if self.dynamic_batch:
            if not len(dims) or not source_shape or dims[0] != source_shape[0]:
                raise ModelError(
                    f"a reshape of {list(source_shape)} to {list(target)} moves the batch axis"
                )
            dims[0] = 0
        return self.initializer(dims, "shape")

    def define(self, tf_name: str, onnx_name: str, shape: tuple[int, ...], layout: Layout) -> None:
        self._values[tf_name] = Value(onnx_name, shape, layout)

    def alias(self, tf_name: str, source: str) -> None:
        if source in self._constants:
            self._constants[tf_name] = self._constants[source]
        else:
            self._values[tf_name] = self.value(source)

    def value(self, tf_name: str) -> Value:
        """The translated tensor of ``tf_name``; a constant becomes a NATIVE initializer."""
        found = self._values.get(tf_name)
        if found is not None:
            return found
        array = self._constants.get(tf_name)
        if array is None:
            raise ModelError(f"node {tf_name} is used before it is defined")
        value = Value(self.initializer(array, tf_name), tuple(array.shape), Layout.NATIVE)
        self._values[tf_name] = value
        return value

    def shape_of(self, tf_name: str) -> tuple[int, ...]:
        array = self._constants.get(tf_name)
        return tuple(array.shape) if array is not None else self.value(tf_name).shape

    def is_constant(self, tf_name: str) -> bool:
        return tf_name in self._constants

    def in_layout(self, value: Value, layout: Layout) -> str:
        """``value`` as an ONNX tensor in ``layout``, adding one cached Transpose if needed."""
        if value.layout is layout:
            return value.name
        if len(value.shape) != 4:
            raise ModelError(f"cannot lay out a rank-{len(value.shape)} tensor as NCHW")
        key = (value.name, layout)
        if key not in self._relaid:
            perm = NHWC_TO_NCHW if layout is Layout.NCHW else NCHW_TO_NHWC
            self._relaid[key] = self.emit(
                "Transpose", [value.name], f"{value.name}/{layout.value}", perm=list(perm)
            )
        return self._relaid[key]

    def operand(self, tf_name: str, layout: Layout) -> str:
        """An input of a broadcasting op in ``layout``; constants are re-laid out, not moved."""
        array = self._constants.get(tf_name)
        if array is None:
            return self.in_layout(self.value(tf_name), layout)
        key = (tf_name, layout)
        if key not in self._constant_operands:
            if layout is Layout.NCHW and array.ndim > 0:
                # TF broadcasts from the trailing (channel) axis: pad to rank 4, then permute.
                array = array.reshape((1,) * (4 - array.ndim) + array.shape)
                array = array.transpose(NHWC_TO_NCHW)
            self._constant_operands[key] = self.initializer(array, tf_name)
        return self._constant_operands[key]

    # ----------------------------------------------------------- nodes

    def emit(
        self,
        op_type: str,
        inputs: Sequence[str],
        hint: str,
        *,
        output: str | None = None,
        **attrs: Any,
    ) -> str:
        """Append one ONNX node and return the name of its single output."""
        out = output if output is not None else self.unique(hint)
        self._used_names.add(out)
        self.nodes.append(
            helper.make_node(
                op_type, list(inputs), [out], name=self.unique(f"{hint}/{op_type}"), **attrs
            )
        )
        return out


def pick_layout(builder: GraphBuilder, tf_names: Iterable[str]) -> Layout:
    """NCHW when every non-constant operand is a 4-D tensor and one of them is already NCHW."""
    names = list(tf_names)
    values = [builder.value(name) for name in names if not builder.is_constant(name)]
    constants_fit = all(len(builder.shape_of(name)) <= 4 for name in names)
    if (
        values
        and constants_fit
        and all(len(v.shape) == 4 for v in values)
        and any(v.layout is Layout.NCHW for v in values)
    ):
        return Layout.NCHW
    return Layout.NATIVE
