"""Read a TensorFlow.js graph model (model.json + weight shards) into a small typed graph.

A TF.js graph model is a TensorFlow GraphDef serialised as JSON (``modelTopology.node``) whose
constant tensors were moved out into binary shards (``weightsManifest``). We decode just enough
of it for a translator: each node with its op, its data inputs and its attributes as plain
Python values, and each constant as a numpy array. Nothing here knows about ONNX.
"""

from __future__ import annotations

import base64
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import EllipsisType
from typing import Any

import numpy as np
import numpy.typing as npt

from common.errors import ModelError

# One decoded attribute: a scalar, a string (decoded from base64 bytes), a shape, or a list.
AttrValue = int | float | bool | str | tuple[Any, ...] | None

# Little-endian dtypes of the manifest; the TF.js converter only writes these for our models.
_MANIFEST_DTYPES: dict[str, np.dtype[Any]] = {
    "float32": np.dtype("<f4"),
    "int32": np.dtype("<i4"),
}


@dataclass(frozen=True, slots=True)
class TfNode:
    """One GraphDef node: ``inputs`` are producer node names (control inputs dropped)."""

    name: str
    op: str
    inputs: tuple[str, ...]
    attrs: Mapping[str, AttrValue]

    def attr_int(self, key: str, default: int = 0) -> int:
        """An integer attribute; the JSON mapping omits zero values, hence the default."""
        value = self.attrs.get(key, default)
        if not isinstance(value, int):
            raise ModelError(f"{self.op} {self.name}: attribute {key}={value!r} is not an int")
        return value

    def attr_strs(self, key: str) -> tuple[str, ...]:
        value = self.attrs.get(key) or ()
        if not isinstance(value, tuple) or not all(isinstance(v, str) for v in value):
            raise ModelError(f"{self.op} {self.name}: attribute {key}={value!r} is not strings")
        return value


@dataclass(frozen=True, slots=True)
class TfGraph:
    """A parsed graph model.

    ``inputs`` maps each graph input (Placeholder node name) to its static shape and
    ``outputs`` lists the node names the signature exposes, in signature order.
    """

    nodes: tuple[TfNode, ...]
    constants: Mapping[str, npt.NDArray[Any]]
    inputs: Mapping[str, tuple[int, ...]]
    outputs: tuple[str, ...]


def load_tfjs_graph(model_json: Path) -> TfGraph:
    """Parse ``model.json`` and the shards next to it; raise ModelError on anything malformed."""
    doc = _read_json(model_json)
    try:
        topology = doc["modelTopology"]
        raw_nodes = topology["node"]
        manifest = doc["weightsManifest"]
    except (KeyError, TypeError) as exc:
        raise ModelError(f"{model_json}: not a TF.js graph model (missing {exc})") from exc
    nodes = tuple(_parse_node(raw, model_json) for raw in raw_nodes)
    constants = _read_weights(manifest, model_json.parent)
    _check_constants(nodes, constants, model_json)
    inputs = {
        node.name: _placeholder_shape(node, model_json)
        for node in nodes
        if node.op == "Placeholder"
    }
    outputs = _signature_outputs(doc, nodes)
    return TfGraph(nodes=nodes, constants=constants, inputs=inputs, outputs=outputs)


def _read_json(path: Path) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ModelError(f"cannot read {path}: {exc.strerror or exc}") from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ModelError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(doc, dict):
        raise ModelError(f"{path}: not a TF.js graph model (top level is not an object)")
    return doc


def _parse_node(raw: Any, source: Path) -> TfNode:
    try:
        name, op = str(raw["name"]), str(raw["op"])
        raw_inputs = raw.get("input", [])
        raw_attrs = raw.get("attr", {})
    except (KeyError, TypeError, AttributeError) as exc:
        raise ModelError(f"{source}: malformed node {str(raw)[:80]!r}") from exc
    inputs = tuple(
        _input_name(item, name, source) for item in raw_inputs if not str(item).startswith("^")
    )
    attrs = {key: _decode_attr(value, name, source) for key, value in raw_attrs.items()}
    return TfNode(name=name, op=op, inputs=inputs, attrs=attrs)


def _input_name(item: Any, node: str, source: Path) -> str:
    """Strip the ``:0`` output index; our ops all have a single output, so ``:1`` is an error."""
    text = str(item)
    producer, _, index = text.partition(":")
    if index not in ("", "0"):
        raise ModelError(f"{source}: node {node} reads output {text}; only output 0 is supported")
    return producer


def _decode_attr(value: Any, node: str, source: Path) -> AttrValue:
    """Decode one AttrValue from protobuf's JSON mapping (int64 as strings, bytes as base64)."""
    if not isinstance(value, dict):
        raise ModelError(f"{source}: node {node} has a malformed attribute {value!r}")
    if "list" in value:
        items = value["list"]
        for kind in ("i", "f", "b", "s", "type", "shape"):
            if kind in items:
                return tuple(_decode_scalar(kind, item) for item in items[kind])
        return ()
    for kind in ("i", "f", "b", "s", "type", "shape"):
        if kind in value:
            return _decode_scalar(kind, value[kind])
    return None  # e.g. "tensor": the value itself lives in the weight shards


def _decode_scalar(kind: str, item: Any) -> AttrValue:
    if kind == "i":
        return int(item)
    if kind == "f":
        return float(item)
    if kind == "b":
        return bool(item)
    if kind == "s":
        return base64.b64decode(item).decode("utf-8")
    if kind == "shape":
        return tuple(int(dim.get("size", 0)) for dim in item.get("dim", []))
    return str(item)


def _read_weights(manifest: Any, folder: Path) -> dict[str, npt.NDArray[Any]]:
    """Read every group's shards, concatenated in manifest order, into named arrays."""
    constants: dict[str, npt.NDArray[Any]] = {}
    try:
        groups = [(list(group["paths"]), list(group["weights"])) for group in manifest]
    except (KeyError, TypeError) as exc:
        raise ModelError(f"{folder}/model.json: malformed weightsManifest") from exc
    for paths, specs in groups:
        buffer = b"".join(_read_shard(folder / str(path)) for path in paths)
        offset = 0
        for spec in specs:
            name, array = _weight_from(buffer, offset, spec, folder)
            constants[name] = array
            offset += array.nbytes
        if offset != len(buffer):
            raise ModelError(
                f"{folder}: shards {paths} hold {len(buffer)} bytes, "
                f"the manifest describes {offset}"
            )
    return constants


def _read_shard(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ModelError(f"cannot read weight shard {path}: {exc.strerror or exc}") from exc


def _weight_from(
    buffer: bytes, offset: int, spec: Any, folder: Path
) -> tuple[str, npt.NDArray[Any]]:
    try:
        name, dtype_name = str(spec["name"]), str(spec["dtype"])
        shape = tuple(int(dim) for dim in spec["shape"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"{folder}: malformed weight entry {str(spec)[:80]!r}") from exc
    if "quantization" in spec:
        raise ModelError(f"{folder}: weight {name} is quantized; only float32/int32 are supported")
    dtype = _MANIFEST_DTYPES.get(dtype_name)
    if dtype is None:
        raise ModelError(f"{folder}: weight {name} has unsupported dtype {dtype_name}")
    count = int(np.prod(shape, dtype=np.int64))
    if offset + count * dtype.itemsize > len(buffer):
        raise ModelError(f"{folder}: weight shards end before weight {name}")
    # Copy so the arrays are writable and do not pin the whole shard buffer.
    flat = np.frombuffer(buffer, dtype=dtype, count=count, offset=offset).copy()
    return name, flat.reshape(shape).astype(dtype.newbyteorder("="), copy=False)


def _check_constants(
    nodes: tuple[TfNode, ...], constants: Mapping[str, object], source: Path
) -> None:
    for node in nodes:
        if node.op == "Const" and node.name not in constants:
            raise ModelError(f"{source}: constant {node.name} has no entry in the weights")


def _placeholder_shape(node: TfNode, source: Path) -> tuple[int, ...]:
    shape = node.attrs.get("shape")
    if not isinstance(shape, tuple) or any(not isinstance(d, int) or d < 1 for d in shape):
        raise ModelError(f"{source}: input {node.name} needs a fully static shape, got {shape}")
    return shape


def _signature_outputs(doc: Mapping[str, Any], nodes: tuple[TfNode, ...]) -> tuple[str, ...]:
    """Outputs from the signature when present, else the nodes nobody consumes."""
    signature = doc.get("signature") or doc.get("userDefinedMetadata", {}).get("signature")
    if isinstance(signature, dict) and isinstance(signature.get("outputs"), dict):
        names = [str(spec.get("name", key)) for key, spec in signature["outputs"].items()]
        return tuple(name.partition(":")[0] for name in names)
    consumed = {name for node in nodes for name in node.inputs}
    return tuple(node.name for node in nodes if node.name not in consumed and node.op != "Const")


@dataclass(frozen=True, slots=True)
class StridedSlicePlan:
    """A TF StridedSlice as an ONNX Slice (over ``axes``) plus, if needed, a Reshape.

    ``sliced_shape`` is the shape after the Slice; ``out_shape`` the TF result, which drops the
    shrunk axes and inserts the new ones.
    """

    starts: tuple[int, ...]
    ends: tuple[int, ...]
    axes: tuple[int, ...]
    steps: tuple[int, ...]
    sliced_shape: tuple[int, ...]
    out_shape: tuple[int, ...]

    @property
    def needs_reshape(self) -> bool:
        return self.sliced_shape != self.out_shape


_IndexItem = slice | int | None  # None: a new axis, int: a shrunk axis
_INT64_MIN = -(2**63)  # an ONNX Slice end "before index 0" for a negative step


def strided_slice_plan(
    shape: Sequence[int],
    begin: npt.ArrayLike,
    end: npt.ArrayLike,
    strides: npt.ArrayLike,
    *,
    begin_mask: int = 0,
    end_mask: int = 0,
    ellipsis_mask: int = 0,
    new_axis_mask: int = 0,
    shrink_axis_mask: int = 0,
) -> StridedSlicePlan:
    """Resolve TF's sparse slice spec (with its five bit masks) against a static shape.

    TF's spec means the same as a numpy index built from it (``x[..., 0:2]``, ``x[:, None]``),
    so we build that index and walk it, which keeps the mask rules in one obvious place.
    """
    spec = [np.asarray(a, dtype=np.int64).reshape(-1) for a in (begin, end, strides)]
    if not len(spec[0]) == len(spec[1]) == len(spec[2]):
        raise ModelError(f"StridedSlice begin/end/strides differ in length: {spec}")
    index: list[_IndexItem | EllipsisType] = []
    for i, (b, e, s) in enumerate(zip(*(a.tolist() for a in spec), strict=True)):
        bit = 1 << i
        if ellipsis_mask & bit:
            index.append(Ellipsis)
        elif new_axis_mask & bit:
            index.append(None)
        elif shrink_axis_mask & bit:
            index.append(int(b))
        else:
            index.append(slice(None if begin_mask & bit else b, None if end_mask & bit else e, s))
    return _plan_from_index(tuple(shape), _expand_ellipsis(index, len(shape)))


def _expand_ellipsis(index: list[_IndexItem | EllipsisType], rank: int) -> list[_IndexItem]:
    """Replace the (first) ellipsis, or the implicit one at the end, by full slices."""
    at = next((i for i, item in enumerate(index) if item is Ellipsis), len(index))
    items = [item for item in index if not isinstance(item, EllipsisType)]
    consumed = sum(1 for item in items if item is not None)
    if consumed > rank:
        raise ModelError(f"StridedSlice indexes {consumed} axes of a rank-{rank} tensor")
    return [*items[:at], *[slice(None)] * (rank - consumed), *items[at:]]


def _plan_from_index(shape: tuple[int, ...], index: list[_IndexItem]) -> StridedSlicePlan:
    starts, ends, axes, steps = [], [], [], []
    sliced, out = list(shape), []
    axis = 0
    for item in index:
        if item is None:
            out.append(1)
            continue
        dim = shape[axis]
        if isinstance(item, int):
            start = item + dim if item < 0 else item
            if not 0 <= start < dim:
                raise ModelError(f"StridedSlice index {item} out of range for size {dim}")
            stop, step, length = start + 1, 1, 1
        else:
            if item.step == 0:
                raise ModelError("StridedSlice stride 0")
            start, stop, step = item.indices(dim)
            length = len(range(start, stop, step))
            out.append(length)
            if step < 0 and stop < 0:
                stop = _INT64_MIN
        if (start, stop, step) != (0, dim, 1):
            starts.append(start)
            ends.append(stop)
            axes.append(axis)
            steps.append(step)
        sliced[axis] = length
        axis += 1
    return StridedSlicePlan(
        starts=tuple(starts),
        ends=tuple(ends),
        axes=tuple(axes),
        steps=tuple(steps),
        sliced_shape=tuple(sliced),
        out_shape=tuple(out),
    )
