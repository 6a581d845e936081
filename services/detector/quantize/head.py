"""The nodes of a detection model that INT8 quantization must leave in float.

The default model's output mixes box coordinates in input pixels (0..640) with probabilities
(0..1) in one tensor, and its decode (grid offsets, anchors, strides, the box scale) runs inside
the graph. Quantizing those ops gives one scale to both ranges, and every score rounds to 0
(/work/shared/CPU_FAST.md, pitfall 1). So the detect layer (its 1x1 output convolutions and the
decode) and everything between it and the graph outputs stay float; the backbone and neck, where
the time goes, are quantized.

The detect layer is found by its scope in the node names: ``tf_detect`` in models converted from
TF.js (the default model), else the last ``/model.<N>/`` module of an Ultralytics ONNX export.
Both quantizers (ONNX Runtime's and NNCF for OpenVINO) take this list.
"""

from __future__ import annotations

import re

import onnx

from common.errors import ModelError

_TF_DETECT = re.compile(r"(^|/)tf_detect/")
_ULTRALYTICS_MODULE = re.compile(r"^/model\.(\d+)/")


def _detect_scope(names: list[str]) -> set[str]:
    tf = {n for n in names if _TF_DETECT.search(n)}
    if tf:
        return tf
    modules = [(int(m.group(1)), n) for n in names if (m := _ULTRALYTICS_MODULE.match(n))]
    if not modules:
        return set()
    last = max(index for index, _ in modules)
    return {n for index, n in modules if index == last}


def head_nodes(model: onnx.ModelProto) -> list[str]:
    """Names of the nodes to keep in float, in graph order: the detect layer and its consumers.

    Raises ModelError when no detect layer can be found by name: quantizing an unknown head
    would silently zero every score, so the caller must not go on.
    """
    nodes = list(model.graph.node)
    keep = _detect_scope([n.name for n in nodes])
    if not keep:
        raise ModelError(
            "cannot find the detection head by name (no 'tf_detect' scope and no '/model.N/' "
            "modules): INT8 quantization needs it kept in float"
        )
    # Everything fed (directly or not) by the head: ONNX lists nodes in topological order.
    tainted = {out for n in nodes if n.name in keep for out in n.output}
    for node in nodes:
        if node.name not in keep and any(i in tainted for i in node.input):
            keep.add(node.name)
            tainted.update(node.output)
    return [n.name for n in nodes if n.name in keep]
