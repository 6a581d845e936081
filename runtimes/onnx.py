"""ONNX Runtime on the CPU.

One intra-op thread per physical core: on SMT machines, two threads sharing a core slow the
convolutions down rather than speeding them up.

Batch: ONNX Runtime runs any batch a model with a dynamic batch takes. With ``max_batch`` 1
(the default: single frames), a batch dimension denoted ``DATA_BATCH`` (the default model's)
is pinned to 1, so that the session is the one a batch-1 export would give; a fixed batch is
the model's own whatever ``max_batch`` says (the Detector cuts batches to it).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType

import numpy as np
import numpy.typing as npt
import onnxruntime as ort
from onnxruntime.capi import onnxruntime_pybind11_state as ort_state

from common.errors import ModelError, one_line
from runtimes.base import Backend, Dim, check_cpu_backend_args

_PRECISIONS = {"tensor(float)": "fp32", "tensor(float16)": "fp16"}
#: ONNX's standard denotation of a batch dimension (modelprep/acquire marks the default model's).
BATCH_DENOTATION = "DATA_BATCH"
_ORT_ERRORS: tuple[type[Exception], ...] = (
    ort_state.Fail,
    ort_state.InvalidArgument,
    ort_state.InvalidGraph,
    ort_state.InvalidProtobuf,
    ort_state.NoModel,
    ort_state.NoSuchFile,
    ort_state.NotImplemented,
    ort_state.RuntimeException,
    RuntimeError,
)


def physical_cores() -> int:
    """Physical cores this process may run on; ``os.cpu_count()`` where that is unknown.

    Counts distinct (package, core) pairs from sysfs over the CPUs in our affinity mask.
    """
    try:
        cpus = sorted(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1
    cores: set[tuple[str, str]] = set()
    for cpu in cpus:
        topology = Path(f"/sys/devices/system/cpu/cpu{cpu}/topology")
        try:
            package = (topology / "physical_package_id").read_text().strip()
            core = (topology / "core_id").read_text().strip()
        except OSError:
            return len(cpus) or os.cpu_count() or 1
        cores.add((package, core))
    return len(cores) or os.cpu_count() or 1


def _dims(shape: list[object] | None) -> tuple[Dim, ...]:
    return tuple(d if isinstance(d, int) and d >= 0 else None for d in (shape or []))


class OnnxBackend:
    """An ``onnxruntime.InferenceSession`` on the CPU execution provider."""

    name = "onnx"
    device = "cpu"

    def __init__(self, model_path: Path, *, threads: int | None = None, max_batch: int = 1) -> None:
        check_cpu_backend_args(model_path, threads, max_batch)
        options = ort.SessionOptions()
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        options.intra_op_num_threads = threads or physical_cores()
        options.log_severity_level = 3  # errors only: warnings would clutter CLI stderr
        # Spinning threads keep a core busy ~50 ms after each run, stolen from the camera and
        # controller on a small robot CPU; not spinning costs about 1 % of inference time.
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        if max_batch == 1:
            options.add_free_dimension_override_by_denotation(BATCH_DENOTATION, 1)
        try:
            session = ort.InferenceSession(
                str(model_path), sess_options=options, providers=["CPUExecutionProvider"]
            )
        except _ORT_ERRORS as exc:
            raise ModelError(f"{model_path}: not a valid ONNX model ({one_line(exc)})") from exc
        self._session: ort.InferenceSession | None = session
        inputs = session.get_inputs()
        if len(inputs) != 1:
            raise ModelError(f"{model_path}: expected one image input, the model has {len(inputs)}")
        self._input_name: str = inputs[0].name
        self._input_dtype = np.float16 if inputs[0].type == "tensor(float16)" else np.float32
        meta = session.get_modelmeta().custom_metadata_map
        # A QDQ INT8 model still takes float input: its quantizer records the precision.
        self.precision: str = meta.get("precision") or _PRECISIONS.get(
            inputs[0].type, inputs[0].type
        )
        self.input_shape: tuple[Dim, ...] = _dims(inputs[0].shape)
        outputs = session.get_outputs()
        self._output_names = [o.name for o in outputs]
        self.output_shapes: tuple[tuple[Dim, ...], ...] = tuple(_dims(o.shape) for o in outputs)
        self.metadata: Mapping[str, str] = MappingProxyType(dict(meta))
        self.threads: int = options.intra_op_num_threads

    def infer(self, batch: npt.NDArray[np.float32]) -> list[npt.NDArray[np.float32]]:
        """Run one batch; outputs are returned as float32 whatever the model's precision."""
        if self._session is None:
            raise ModelError("inference on a closed onnx backend")
        feed = batch if batch.dtype == self._input_dtype else batch.astype(self._input_dtype)
        try:
            outputs = self._session.run(self._output_names, {self._input_name: feed})
        except _ORT_ERRORS as exc:
            raise ModelError(f"inference failed: {one_line(exc)}") from exc
        return [np.asarray(o, dtype=np.float32) for o in outputs]

    def close(self) -> None:
        """Drop the session; ONNX Runtime frees it when the last reference goes."""
        self._session = None


def load(model_path: Path, *, threads: int | None = None, max_batch: int = 1) -> Backend:
    """Open ``model_path`` with ONNX Runtime on the CPU (``threads``: intra-op threads;
    ``max_batch``: the largest batch it will be given, see the module's doc)."""
    return OnnxBackend(model_path, threads=threads, max_batch=max_batch)
