"""TF.js graph models built by hand for the translator and fetch tests: ``model.json`` + shard."""

from __future__ import annotations

import base64
import json
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[Any]


def _attr(value: Any) -> dict[str, Any]:
    if isinstance(value, bool):
        return {"b": value}
    if isinstance(value, int):
        return {"i": str(value)}
    if isinstance(value, str):
        return {"s": base64.b64encode(value.encode()).decode()}
    if value and isinstance(value[0], str):
        return {"list": {"s": [base64.b64encode(v.encode()).decode() for v in value]}}
    return {"list": {"i": [str(v) for v in value]}}


class TfjsModel:
    """Builds a graph model: call ``const``/``op`` in order, then ``write``."""

    def __init__(self, input_shape: tuple[int, ...]) -> None:
        self.input_shape = input_shape
        shape = {"dim": [{"size": str(d)} for d in input_shape]}
        self.nodes: list[dict[str, Any]] = [
            {
                "name": "input_1",
                "op": "Placeholder",
                "attr": {"dtype": {"type": "DT_FLOAT"}, "shape": {"shape": shape}},
            }
        ]
        self.weights: list[tuple[str, Array]] = []

    def const(self, name: str, value: Any, dtype: Any = np.float32) -> str:
        self.weights.append((name, np.asarray(value, dtype=dtype)))
        self.nodes.append({"name": name, "op": "Const", "attr": {}})
        return name

    def op(self, name: str, op: str, inputs: list[str], **attrs: Any) -> str:
        self.nodes.append(
            {
                "name": name,
                "op": op,
                "input": inputs,
                "attr": {k: _attr(v) for k, v in attrs.items()},
            }
        )
        return name

    def write(self, folder: Path, output: str) -> Path:
        manifest = [
            {"name": n, "shape": list(a.shape), "dtype": str(a.dtype)} for n, a in self.weights
        ]
        (folder / "group1-shard1of1.bin").write_bytes(
            b"".join(a.astype(a.dtype.newbyteorder("<")).tobytes() for _, a in self.weights)
        )
        self.op("Identity", "Identity", [output])
        doc = {
            "format": "graph-model",
            "modelTopology": {"node": self.nodes},
            "signature": {"outputs": {"out": {"name": "Identity:0"}}},
            "weightsManifest": [{"paths": ["group1-shard1of1.bin"], "weights": manifest}],
        }
        (folder / "model.json").write_text(json.dumps(doc))
        return folder / "model.json"


def fused_conv(
    model: TfjsModel,
    name: str,
    x: str,
    w: Array,
    b: Array,
    *,
    stride: int = 1,
    dilation: int = 1,
    padding: str = "SAME",
    fused: tuple[str, ...] = ("BiasAdd",),
) -> str:
    inputs = [x, model.const(f"{name}/w", w), model.const(f"{name}/b", b)]
    return model.op(
        name,
        "_FusedConv2D",
        inputs,
        padding=padding,
        data_format="NHWC",
        strides=[1, stride, stride, 1],
        dilations=[1, dilation, dilation, 1],
        fused_ops=list(fused),
        num_args=1,
    )
