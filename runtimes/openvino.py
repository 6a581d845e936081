"""OpenVINO on the CPU: an optional extra (``pip install .[openvino]``), FP32 or NNCF INT8.

The model is an ONNX file, read by OpenVINO's own importer, or an OpenVINO IR (``.xml``) such
as the one NNCF writes (:mod:`modelprep.quantize.nncf_int8`). It is compiled for the
CPU with the LATENCY hint (one stream, every thread on one request: the stack sends single
frames) and ``threads`` inference threads, one per physical core by default as for ONNX
Runtime. The inference precision is pinned to f32: on CPUs with AMX, OpenVINO would otherwise
run in bf16, whose 8-bit mantissa rounds box coordinates near 640 px to 4 px steps.

Batch: a model with a dynamic batch is reshaped before it is compiled: to a batch of 1 for
``max_batch`` 1 (the default: single frames, compiled as a batch-1 export would be), else to
a batch bounded by 1..``max_batch`` (one compiled model runs every batch size up to it). A fixed
batch is the model's own whatever ``max_batch`` says (the Detector cuts batches to it).

Precisions: ``fp32`` runs the model as it is; ``int8`` runs an NNCF-quantized IR (the head and
decode kept in float). An IR's precision is its own: FakeQuantize ops in it mean INT8.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

from common.errors import BackendUnavailable, ConfigError, ModelError, one_line
from common.model_metadata import OPENVINO_METADATA_KEY
from runtimes.base import Backend, Dim, check_cpu_backend_args
from runtimes.onnx import physical_cores
from runtimes.profiles import read_onnx_input

INSTALL = "pip install '.[openvino]'"
PRECISIONS = ("fp32", "int8")
#: Where :mod:`~modelprep.quantize.nncf_int8` puts the ONNX metadata in an IR.
METADATA_KEY = OPENVINO_METADATA_KEY

try:
    import openvino as ov
except ImportError as exc:  # the extra is not installed: one line, and auto skips us
    raise BackendUnavailable(f"OpenVINO is not installed ({INSTALL}): {exc}") from exc


def _dims(shape: Any) -> tuple[Dim, ...]:
    return tuple(d.get_length() if d.is_static else None for d in shape)


def is_ir(path: Path) -> bool:
    """Whether ``path`` names OpenVINO IR (its weights in the ``.bin`` beside it)."""
    return path.suffix == ".xml"


def _ir_metadata(model: Any) -> dict[str, str]:
    if not model.has_rt_info([METADATA_KEY]):
        return {}
    return {k: v.astype(str) for k, v in model.get_rt_info()[METADATA_KEY].items()}


def _is_int8(model: Any) -> bool:
    return any(op.get_type_name() == "FakeQuantize" for op in model.get_ordered_ops())


def _bound_batch(model: Any, max_batch: int) -> None:
    """Reshape a dynamic batch to 1 (``max_batch`` 1) or to 1..``max_batch``; a fixed one,
    or an input that is not 4-D, is left as it is."""
    shape = model.inputs[0].get_partial_shape()
    if shape.rank.is_dynamic or len(shape) != 4 or shape[0].is_static:
        return
    batch = ov.Dimension(1) if max_batch == 1 else ov.Dimension(1, max_batch)
    try:
        model.reshape({model.inputs[0]: ov.PartialShape([batch, *(shape[i] for i in (1, 2, 3))])})
    except RuntimeError as exc:
        raise ModelError(
            f"OpenVINO cannot set the model's batch to {batch} ({one_line(exc)})"
        ) from exc


class OpenVinoBackend:
    """A model compiled by OpenVINO for the CPU, with one reused infer request."""

    name = "openvino"
    device = "cpu"

    def __init__(
        self,
        model_path: Path,
        *,
        precision: str = "",
        threads: int | None = None,
        max_batch: int = 1,
    ) -> None:
        check_cpu_backend_args(model_path, threads, max_batch)
        core = ov.Core()
        try:
            model = core.read_model(str(model_path))
        except RuntimeError as exc:  # OpenVINO's errors are RuntimeError subclasses
            raise ModelError(
                f"{model_path}: not a model OpenVINO can read ({one_line(exc)})"
            ) from exc
        if len(model.inputs) != 1:
            raise ModelError(
                f"{model_path}: expected one image input, the model has {len(model.inputs)}"
            )
        _bound_batch(model, max_batch)
        own = "int8" if _is_int8(model) else "fp32"
        if precision and precision != own:
            raise ConfigError(
                f"{model_path} is an {own} model; openvino cannot run it as {precision}"
            )
        metadata = _ir_metadata(model) if is_ir(model_path) else read_onnx_input(model_path)[1]
        self.threads: int = threads or physical_cores()
        hint = ov.properties.hint
        config = {
            hint.performance_mode: hint.PerformanceMode.LATENCY,
            hint.inference_precision: ov.Type.f32,
            ov.properties.inference_num_threads: self.threads,
        }
        try:
            compiled = core.compile_model(model, "CPU", config)
        except RuntimeError as exc:
            raise ModelError(f"{model_path}: OpenVINO cannot compile it ({one_line(exc)})") from exc
        self._request: Any = compiled.create_infer_request()
        self._outputs = list(compiled.outputs)
        self.precision: str = own
        self.input_shape: tuple[Dim, ...] = _dims(compiled.inputs[0].get_partial_shape())
        self.output_shapes: tuple[tuple[Dim, ...], ...] = tuple(
            _dims(o.get_partial_shape()) for o in self._outputs
        )
        self.metadata: Mapping[str, str] = MappingProxyType(metadata)

    def infer(self, batch: npt.NDArray[np.float32]) -> list[npt.NDArray[np.float32]]:
        """Run one batch; outputs are copied out (the request's buffers are reused)."""
        if self._request is None:
            raise ModelError("inference on a closed openvino backend")
        feed = np.ascontiguousarray(batch, dtype=np.float32)
        try:
            results = self._request.infer({0: feed})
        except RuntimeError as exc:
            raise ModelError(f"inference failed: {one_line(exc)}") from exc
        return [np.array(results[o], dtype=np.float32) for o in self._outputs]

    def close(self) -> None:
        """Drop the request and the compiled model; OpenVINO frees them with the last reference."""
        self._request = None
        self._outputs = []


def load(
    model_path: Path, *, precision: str = "", threads: int | None = None, max_batch: int = 1
) -> Backend:
    """Open ``model_path`` (ONNX or IR) with OpenVINO on the CPU.

    ``precision``: ``fp32`` or ``int8``; empty takes the model's own (fp32 for ONNX).
    ``threads``: inference threads, one per physical core by default. ``max_batch``: the
    largest batch it will be given (see the module's doc).
    """
    if precision and precision not in PRECISIONS:
        raise ConfigError(f"openvino takes precision {' or '.join(PRECISIONS)}, not {precision!r}")
    if precision == "int8" and not is_ir(model_path):
        # One INT8 entry point: modelprep.quantize.quantized_model (the detector's variants
        # call it for detector.precision = "int8") writes the IR this loads.
        raise ConfigError(
            f"openvino int8 loads a quantized IR (.xml), not {model_path.name}: set "
            'detector.precision = "int8" (the detector quantizes and caches it), or pass the IR'
        )
    return OpenVinoBackend(model_path, precision=precision, threads=threads, max_batch=max_batch)
