"""From settings to the model file a backend loads: input size, precision, fast profile.

A *variant* is ``backend:precision:imgsz`` (``onnx:int8:480``). :func:`prepare` turns
DetectorSettings into one: the model at that input size (the default model is rebuilt for it;
a named model must already have it), then, for ``int8`` on a runtime we quantize for
(:data:`QUANT_RUNTIMES`), the INT8 model from :mod:`modelprep.quantize`. An INT8 model
that cannot be built leaves the detector on FP32, with one warning line and a ``note``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from common.contracts import BackendName
from common.errors import ConfigError, ModelError
from common.lifecycle import Progress, print_progress
from modelprep.files import NATIVE_IMGSZ, ensure_default_model
from runtimes.select import backend_options
from services.detector.contract import DetectorSettings
from services.detector.pipeline import Detector

log = logging.getLogger("runtimes.variants")

#: Backend -> the runtime whose quantizer builds its INT8 model.
QUANT_RUNTIMES = {"onnx": "onnxruntime", "openvino": "openvino"}


@dataclass(frozen=True, slots=True)
class Variant:
    """One way to run the model: ``backend``, ``precision`` and input size ``imgsz``."""

    backend: str
    precision: str
    imgsz: int

    @classmethod
    def parse(cls, text: str) -> Variant:
        """``onnx:int8:480`` -> Variant; ConfigError naming the text otherwise."""
        parts = text.strip().split(":")
        if len(parts) != 3 or not parts[2].isdigit():
            raise ConfigError(
                f"variant {text!r} must be backend:precision:size, e.g. onnx:int8:480"
            )
        return cls(parts[0], parts[1], int(parts[2]))

    @property
    def label(self) -> str:
        return f"{self.backend}:{self.precision}:{self.imgsz}"

    def settings(self, base: DetectorSettings) -> DetectorSettings:
        """``base`` running this variant (and no profile: the variant is already chosen)."""
        try:
            backend = BackendName(self.backend)
        except ValueError as exc:
            raise ConfigError(f"variant {self.label}: unknown backend {self.backend!r}") from exc
        return replace(
            base,
            backend=backend,
            precision=self.precision,
            imgsz=self.imgsz,
            profile="default",
        )


@dataclass(frozen=True, slots=True)
class Prepared:
    """What to load: ``model`` on ``backend`` with ``options``; ``note`` says why it is not
    quite what was asked ("" when it is)."""

    model: Path
    backend: str
    options: dict[str, Any]
    note: str = ""


def model_input_hw(model: Path) -> tuple[int | None, int | None]:
    """The (height, width) an ONNX model's image input declares; None where dynamic."""
    import onnx

    try:
        graph = onnx.load(str(model), load_external_data=False).graph
    except (OSError, ValueError) as exc:
        raise ModelError(f"{model}: not a readable ONNX model ({exc})") from exc
    initializers = {i.name for i in graph.initializer}
    inputs = [i for i in graph.input if i.name not in initializers]
    dims = [d.dim_value or None for d in inputs[0].type.tensor_type.shape.dim] if inputs else []
    return (dims[2], dims[3]) if len(dims) == 4 else (None, None)


def sized_model(s: DetectorSettings, progress: Progress = print_progress) -> Path:
    """The model file at ``s.imgsz``: the default model (rebuilt for that size when needed), or
    ``s.model``, whose fixed input must then be that size (ConfigError otherwise)."""
    if not s.model:
        return ensure_default_model(progress=progress, imgsz=s.imgsz)
    path = Path(s.model)
    if s.imgsz and path.suffix == ".onnx" and path.is_file():
        height, width = model_input_hw(path)
        if (height, width) != (s.imgsz, s.imgsz):
            own = f"{height}x{width}" if height and width else "dynamic"
            raise ConfigError(
                f"detector.imgsz = {s.imgsz}, but {path.name} has a {own} input: "
                "set imgsz = 0 to use the model's own size (only the default model is rebuilt)"
            )
    return path


def finds_objects(reference: Path, backend: str) -> Callable[[Path], str | None]:
    """A check for an INT8 model: on the calibration photos it must find something wherever
    the FP32 ``reference`` does (a quantization that wiped the scores finds nothing)."""

    def check(candidate: Path) -> str | None:
        from modelprep.quantize.calibration import calibration_photos

        photos = [image for label, image in calibration_photos() if label.endswith(":full")]
        with (
            Detector.open(reference, backend=backend) as fp32,
            Detector.open(candidate, backend=backend) as int8,
        ):
            expected = sum(1 for p in photos if len(fp32.detect(p)))
            found = sum(1 for p in photos if len(int8.detect(p)) and len(fp32.detect(p)))
        if found < expected:
            return (
                f"it finds nothing on {expected - found} of {expected} photos FP32 finds objects in"
            )
        return None

    return check


def prepare(
    s: DetectorSettings, progress: Progress = print_progress, max_batch: int = 1
) -> Prepared:
    """The model, backend and options for settings ``s`` (profile already resolved), for
    batches of up to ``max_batch`` frames."""
    model = sized_model(s, progress)
    runtime = QUANT_RUNTIMES.get(s.backend)
    if runtime is None:
        return Prepared(model, s.backend, backend_options(s, max_batch))
    if s.precision not in ("", "fp32", "int8"):
        raise ConfigError(
            f"detector.precision {s.precision!r} is not for backend {s.backend}: use fp32 or int8"
        )
    options = backend_options(replace(s, precision=""), max_batch)
    if s.precision != "int8":
        return Prepared(model, s.backend, options)
    from modelprep.quantize import QuantizationFailed, quantized_model

    try:
        quantized = quantized_model(
            model,
            runtime=runtime,
            calibration_dir=Path(s.calibration_dir) if s.calibration_dir else None,
            check=finds_objects(model, s.backend),
            progress=progress,
        )
    except QuantizationFailed as exc:
        note = f"{exc}; the detector stays on FP32"
        log.warning("%s", note)
        return Prepared(model, s.backend, options, note)
    return Prepared(quantized, s.backend, options)


def open_prepared(
    s: DetectorSettings, progress: Progress = print_progress, max_batch: int = 1
) -> tuple[Detector, str]:
    """The Detector for settings ``s`` (profile already resolved), for batches of up to
    ``max_batch`` frames, and its note."""
    prepared = prepare(s, progress, max_batch)
    det = Detector.open(prepared.model, backend=prepared.backend, settings=s, **prepared.options)
    return det, prepared.note


def variant_of(det: Detector) -> str:
    """What a loaded detector runs, as a variant label."""
    size = det.info.input_height if det.info.input_height else NATIVE_IMGSZ
    return f"{det.backend.name}:{det.backend.precision}:{size}"
