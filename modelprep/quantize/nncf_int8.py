"""INT8 for OpenVINO: NNCF post-training static quantization, written as OpenVINO IR.

NNCF (OpenVINO's own quantization tool) calibrates activation ranges on the given frames and
inserts FakeQuantize ops that OpenVINO's CPU plugin runs as INT8 kernels. The MIXED preset
(symmetric weights, asymmetric activations) suits the SiLU activations of YOLO models better
than the default symmetric one (docs/benchmarks.md, "Earlier CPU measurements"). ``keep_float``
(from :func:`modelprep.quantize.head.head_nodes`) names ONNX nodes; OpenVINO's importer
keeps those names as its ops' friendly names, except that a convolution with a bias becomes
``<name>/WithoutBiases`` plus an Add called ``<name>``, and a node whose output is a graph
output takes the output's name (``output0/Mul`` becomes ``output0``). :func:`openvino_names`
maps one to the other, and refuses a name it cannot find.

The model's metadata (class names, input size) is copied into the IR's runtime info under
:data:`METADATA_KEY`, so that the IR is a complete model on its own.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path

import nncf
import numpy as np
import onnx
import openvino as ov

from common.errors import ModelError
from common.model_metadata import OPENVINO_METADATA_KEY as METADATA_KEY


def openvino_names(
    ov_model: ov.Model, onnx_model: onnx.ModelProto, names: Iterable[str]
) -> list[str]:
    """The OpenVINO op names (friendly names) that carry out the ONNX nodes called ``names``.

    Raises ModelError for a name no op stands for.
    """
    wanted = set(names)
    outputs = {o: n.name for n in onnx_model.graph.node if n.name in wanted for o in n.output}
    found: set[str] = set()
    matched: list[str] = []
    for op in ov_model.get_ordered_ops():
        if op.get_type_name() in ("Constant", "Parameter", "Result"):
            continue
        name = op.get_friendly_name()
        by_name = (
            name if name in wanted else next((w for w in wanted if name.startswith(f"{w}/")), None)
        )
        tensors = {t for out in op.outputs() for t in out.get_names()}
        by_tensor = next((outputs[t] for t in tensors if t in outputs), None)
        source = by_name or by_tensor
        if source is not None:
            found.add(source)
            matched.append(name)
    missing = sorted(wanted - found)
    if missing:
        raise ModelError(
            f"{len(missing)} node(s) to keep float have no OpenVINO op, e.g. {missing[0]!r}"
        )
    return matched


def quantize(
    model: Path, out: Path, frames: Sequence[np.ndarray], *, keep_float: Sequence[str]
) -> None:
    """Quantize the ONNX ``model`` to INT8 with NNCF and write OpenVINO IR to ``out`` (.xml).

    ``frames`` are preprocessed ``[1, 3, H, W]`` float32 inputs (the calibration set, one
    statistics pass each); ``keep_float`` names the ONNX nodes to leave in float.
    """
    if not frames:
        raise ModelError("INT8 calibration needs at least one frame")
    if out.suffix != ".xml":
        raise ModelError(f"{out}: OpenVINO IR must be written to an .xml path")
    onnx_model = onnx.load(str(model), load_external_data=False)
    ov_model = ov.Core().read_model(str(model))
    ignored = openvino_names(ov_model, onnx_model, keep_float)
    # NNCF logs a line per ignored node on stdout; the caller prints its own progress.
    nncf.set_log_level(logging.WARNING)
    # Its progress bar is drawn on stdout, which carries a command's result: move it to stderr.
    with contextlib.redirect_stdout(sys.stderr):
        quantized = nncf.quantize(
            ov_model,
            nncf.Dataset(list(frames)),
            preset=nncf.QuantizationPreset.MIXED,
            subset_size=len(frames),
            ignored_scope=nncf.IgnoredScope(names=ignored),
        )
    for prop in onnx_model.metadata_props:
        quantized.set_rt_info(prop.value, [METADATA_KEY, prop.key])
    out.parent.mkdir(parents=True, exist_ok=True)
    ov.save_model(quantized, str(out))
