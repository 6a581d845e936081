"""Rebuild a YOLOv5 TF.js graph for another square input size.

The TF.js export bakes its input size into the graph: the placeholder shape, the two upsample
sizes, and per detection level the grid offsets, the stride and the anchors (both divided by
the input size, because TF.js boxes come out normalised), the two head Reshape shapes; our
converter adds the box scale. All of them follow from one number, the input size, so
:func:`resize_yolov5_graph` derives every one of them from ``size`` and the graph itself:

* ``Placeholder``: ``(1, size, size, 3)``.
* ``ResizeNearestNeighbor`` sizes: scaled by ``size / original``.
* ``Reshape`` shapes under ``tf_detect``: a cell count ``g*g`` (or ``anchors*g*g``) of a level at
  the original size becomes that of the same level at ``size``.
* ``Add`` under ``tf_detect`` with a ``(1, 1, g*g, 2)`` constant: the grid ``(x - 0.5, y - 0.5)``,
  checked against the original and rebuilt for the new ``g``.
* ``Mul`` under ``tf_detect`` whose other input is that ``Add`` (stride / size) or a ``Square``
  (anchors / size): multiplied by ``original / size``.

Anything that does not look exactly like that raises ModelError: we never guess a constant.
Every rewrite is counted, and the count must be the graph's levels times five plus two.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from common.errors import ModelError
from modelprep.acquire.tfjs_graph import TfGraph, TfNode

STRIDES = (8, 16, 32)  # YOLOv5's P3, P4, P5
MIN_SIZE, MAX_SIZE = 160, 1280
DETECT_SCOPE = "tf_detect"


def check_size(size: int) -> None:
    """ModelError unless ``size`` is a multiple of 32 within MIN_SIZE..MAX_SIZE."""
    if size % 32 or not MIN_SIZE <= size <= MAX_SIZE:
        raise ModelError(
            f"input size must be a multiple of 32 in {MIN_SIZE}..{MAX_SIZE}, got {size}"
        )


def grid_offsets(cells: int) -> npt.NDArray[np.float32]:
    """YOLOv5's TF grid for a ``cells x cells`` level: ``(x - 0.5, y - 0.5)``, x fastest."""
    ys, xs = np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij")
    grid = np.stack([xs.ravel(), ys.ravel()], axis=-1).astype(np.float32) - 0.5
    return grid.reshape(1, 1, cells * cells, 2)


def input_size(graph: TfGraph) -> int:
    """The square input size of a one-input NHWC graph; ModelError otherwise."""
    shapes = list(graph.inputs.values())
    if len(shapes) != 1 or len(shapes[0]) != 4 or shapes[0][1] != shapes[0][2]:
        raise ModelError(f"expected one square NHWC input, got {shapes}")
    return int(shapes[0][1])


def resize_yolov5_graph(graph: TfGraph, size: int) -> TfGraph:
    """``graph`` with every size-dependent constant rebuilt for a ``size x size`` input."""
    check_size(size)
    original = input_size(graph)
    ratio = original / size
    levels = {(original // s) ** 2: size // s for s in STRIDES}  # old cells -> new side
    anchors = _anchor_count(graph)
    by_name = {node.name: node for node in graph.nodes}
    constants: dict[str, npt.NDArray[Any]] = dict(graph.constants)
    rewritten: set[str] = set()

    def replace(name: str, value: npt.NDArray[Any]) -> None:
        if name in rewritten:
            return
        constants[name] = value.astype(graph.constants[name].dtype)
        rewritten.add(name)

    for node in graph.nodes:
        detect = DETECT_SCOPE in node.name
        if node.op == "ResizeNearestNeighbor":
            old = graph.constants[node.inputs[1]]
            replace(node.inputs[1], _scaled_exact(old, size, original, node))
        elif detect and node.op == "Reshape":
            replace(node.inputs[1], _reshape_dims(graph, node, levels, anchors))
        elif detect and node.op == "Add":
            name, old = _constant_input(graph, node)
            cells = old.shape[2] if old.ndim == 4 else 0
            if cells not in levels or not np.array_equal(old, grid_offsets(int(cells**0.5))):
                raise ModelError(f"{node.name}: {old.shape} is not a YOLOv5 grid")
            replace(name, grid_offsets(levels[cells]))
        elif detect and node.op == "Mul":
            producer = _variable_input(graph, node)
            if by_name[producer].op in ("Add", "Square"):  # stride / size, anchors / size
                name, old = _constant_input(graph, node)
                replace(name, old * np.float32(ratio))
    expected = 5 * len(levels) + 2
    if len(rewritten) != expected:
        raise ModelError(
            f"found {len(rewritten)} size-dependent constants, expected {expected}: "
            "not a YOLOv5 TF.js graph this converter knows"
        )
    ((placeholder, shape),) = graph.inputs.items()
    inputs = {placeholder: (shape[0], size, size, shape[3])}
    return dataclasses.replace(graph, constants=constants, inputs=inputs)


def _anchor_count(graph: TfGraph) -> int:
    """Anchors per cell, from the shape of the first anchors constant ``(1, na, 1, 2)``."""
    for name, value in graph.constants.items():
        shape = value.shape
        if (
            DETECT_SCOPE in name
            and len(shape) == 4
            and shape[0] == shape[2] == 1 < shape[1]
            and shape[3] == 2
        ):
            return int(shape[1])
    raise ModelError("no anchors constant (1, anchors, 1, 2) in the detect head")


def _scaled_exact(
    old: npt.NDArray[Any], size: int, original: int, node: TfNode
) -> npt.NDArray[Any]:
    scaled = old.astype(np.int64) * size
    if np.any(scaled % original):
        raise ModelError(f"{node.name}: {old.tolist()} does not scale to size {size}")
    return scaled // original


def _reshape_dims(
    graph: TfGraph, node: TfNode, levels: Mapping[int, int], anchors: int
) -> npt.NDArray[Any]:
    old = graph.constants[node.inputs[1]].astype(np.int64)
    new = old.copy()
    found = 0
    for i, dim in enumerate(old.tolist()):
        for cells, side in levels.items():
            if dim in (cells, anchors * cells):
                new[i] = dim // cells * side * side
                found += 1
    if found != 1:
        raise ModelError(f"{node.name}: cannot tell the cell count in shape {old.tolist()}")
    return new


def _constant_input(graph: TfGraph, node: TfNode) -> tuple[str, npt.NDArray[Any]]:
    names = [n for n in node.inputs if n in graph.constants]
    if len(names) != 1:
        raise ModelError(f"{node.name}: expected exactly one constant input")
    return names[0], graph.constants[names[0]]


def _variable_input(graph: TfGraph, node: TfNode) -> str:
    names = [n for n in node.inputs if n not in graph.constants]
    if len(names) != 1:
        raise ModelError(f"{node.name}: expected exactly one non-constant input")
    return names[0]
