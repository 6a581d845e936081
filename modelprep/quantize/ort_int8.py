"""INT8 by ONNX Runtime's own post-training static quantization (never a hand-written one).

Settings measured on a 2-core AVX2 machine without VNNI (docs/detector.md): QDQ format,
activations U8 and weights S8 (S8S8 runs slower than FP32 there), ``reduce_range`` (7-bit
weights: without it U8S8 saturates the AVX2 kernels' 16-bit accumulators) and per-channel
weights. The nodes in ``keep_float`` stay float: the detection head and its decode mix pixel
coordinates (0..640) and probabilities (0..1) in one tensor, which one INT8 scale cannot hold.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt
import onnx
from onnxruntime.quantization import (
    CalibrationDataReader,
    CalibrationMethod,
    QuantFormat,
    QuantType,
    quantize_static,
)

from modelprep.int8_cache import QUANTIZER_SETTINGS

#: What this module produces (declared with the cache, whose key it is part of: serving looks
#: the INT8 model up without importing this module); a change there re-quantizes.
SETTINGS = QUANTIZER_SETTINGS["onnxruntime"]


class _Frames(CalibrationDataReader):  # type: ignore[misc]  # onnxruntime is untyped
    """Hands ONNX Runtime's calibrator one preprocessed frame at a time."""

    def __init__(self, input_name: str, frames: Sequence[npt.NDArray[np.float32]]) -> None:
        self._input_name = input_name
        self._frames = frames
        self._next: Iterator[npt.NDArray[np.float32]] = iter(frames)

    def get_next(self) -> dict[str, npt.NDArray[np.float32]] | None:
        frame = next(self._next, None)
        return None if frame is None else {self._input_name: frame}

    def rewind(self) -> None:
        self._next = iter(self._frames)


# ONNX Runtime logs this on the root logger for every model not run through its
# shape-inference pre-processing script; ours is quantized as it is, on purpose (the decode head
# stays float), so the advice is noise in the detector's log.
# (Two wordings in onnxruntime 1.32, one per entry point.)
_PREPROCESS_ADVICE = "pre-processing before quantization"


class _DropAdvice(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return _PREPROCESS_ADVICE not in str(record.msg)


@contextlib.contextmanager
def _without_preprocess_advice() -> Iterator[None]:
    root = logging.getLogger()
    advice = _DropAdvice()
    root.addFilter(advice)
    try:
        yield
    finally:
        root.removeFilter(advice)


def quantize(
    model: Path,
    out: Path,
    frames: Sequence[npt.NDArray[np.float32]],
    *,
    keep_float: Sequence[str],
) -> None:
    """Write ``out``: ``model`` quantized to INT8, calibrated on ``frames`` (NCHW float32
    network inputs), the nodes named in ``keep_float`` left in float."""
    graph = onnx.load(str(model), load_external_data=False).graph
    initializers = {init.name for init in graph.initializer}
    inputs = [i.name for i in graph.input if i.name not in initializers]
    if len(inputs) != 1:
        raise ValueError(f"expected one image input, the model has {len(inputs)}")
    with _without_preprocess_advice():
        quantize_static(
            str(model),
            str(out),
            _Frames(inputs[0], frames),
            quant_format=QuantFormat.QDQ,
            activation_type=QuantType.QUInt8,
            weight_type=QuantType.QInt8,
            per_channel=True,
            reduce_range=True,
            calibrate_method=CalibrationMethod.MinMax,
            nodes_to_exclude=list(keep_float),
        )
    quantized = onnx.load(str(out))
    props = {p.key: p.value for p in quantized.metadata_props}
    onnx.helper.set_model_props(quantized, {**props, "precision": "int8"})
    onnx.save(quantized, str(out))
