"""The nodes of a detection model that INT8 quantization must leave in float.

The default model's output mixes box coordinates in input pixels (0..640) with probabilities
(0..1) in one tensor, and its decode (grid offsets, anchors, strides, the box scale) runs inside
the graph. Quantizing those ops gives one scale to both ranges, and every score rounds to 0
(docs/detector.md, "INT8"). So the last convolutions (the detect layer) and everything
after them stay float; the backbone and neck, where the time goes, are quantized. The rule is
structural (no Conv depends on the node), so it needs no naming convention. Both quantizers
(ONNX Runtime's and NNCF for OpenVINO) take this list.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


def head_nodes(model: Path) -> list[str]:
    """The nodes to keep in float: every node no Conv depends on, i.e. the last Convs (the
    detection head) and everything after them (the decode, the output scale)."""
    import onnx

    graph = onnx.load(str(model), load_external_data=False).graph
    consumers: dict[str, list[Any]] = {}
    for node in graph.node:
        for name in node.input:
            consumers.setdefault(name, []).append(node)
    feeds_conv: dict[str, bool] = {}

    def leads_to_conv(node: Any) -> bool:  # memoised walk downstream, iterative-safe depth
        if node.name not in feeds_conv:
            feeds_conv[node.name] = False
            nexts = [n for out in node.output for n in consumers.get(out, [])]
            feeds_conv[node.name] = any(n.op_type == "Conv" or leads_to_conv(n) for n in nexts)
        return feeds_conv[node.name]

    return [node.name for node in graph.node if not leads_to_conv(node)]
