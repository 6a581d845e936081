"""From a model spec to the model file a backend loads, as prepared: input size, precision.

A *variant* is ``backend:precision:imgsz`` (``onnx:int8:480``). :func:`locate` finds the files
a ModelSpec needs, as ``zstack prepare`` made them (preparing.py builds them: the model at that
input size, the default model rebuilt for it, and, for ``int8`` on a runtime we quantize for
(:data:`QUANT_RUNTIMES`), the INT8 model), and builds nothing: what is missing raises
:class:`NotPrepared`, one line naming it and what to run. An INT8 model whose build failed
leaves the detector on FP32, with one warning line and a ``note``. This module reaches no
quantizer: it looks the INT8 model up in modelprep/int8_cache.py.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

from common.contracts import BackendName
from common.errors import ConfigError, ModelError
from modelprep.files import NATIVE_IMGSZ, current_default_model, default_model_path
from modelprep.int8_cache import QuantizationFailed, cached_model, slot
from perception.pipeline import Detector
from perception.settings import DetectorSpec, ModelSpec
from runtimes.select import backend_options

log = logging.getLogger("perception.variants")

#: Backend -> the runtime whose quantizer builds its INT8 model.
QUANT_RUNTIMES = {"onnx": "onnxruntime", "openvino": "openvino"}
#: What a user runs to prepare the models a stack config needs, ahead of serving.
PREPARE_COMMAND = "zstack prepare"

Spec = TypeVar("Spec", bound=ModelSpec)


class NotPrepared(ConfigError):
    """A file serving needs that was not prepared ahead: ``missing`` says which, and the one
    line says what to run (``command``, by default :data:`PREPARE_COMMAND`)."""

    def __init__(self, missing: str, command: str = PREPARE_COMMAND) -> None:
        super().__init__(f"{missing}: run `{command}`")
        self.missing = missing
        self.command = command

    def to_run(self, command: str) -> NotPrepared:
        """The same, saying to run ``command`` (one that names the config file, say)."""
        return NotPrepared(self.missing, command)


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

    def settings(self, base: Spec) -> Spec:
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


def named_model(s: ModelSpec) -> Path:
    """``s.model``, whose fixed input must be ``s.imgsz`` when that is set (ConfigError
    otherwise): a named model is never rebuilt."""
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


def located_model(s: ModelSpec) -> Path:
    """The model file at ``s.imgsz``, never building it: ``s.model``, or the default model
    at that size, which must be there and current (NotPrepared otherwise)."""
    if s.model:
        return named_model(s)  # the user's own file: nothing is built for it
    path = current_default_model(imgsz=s.imgsz)
    if path is None:
        size = f" at input size {s.imgsz}" if s.imgsz not in (0, NATIVE_IMGSZ) else ""
        where = default_model_path(imgsz=s.imgsz)
        raise NotPrepared(f"the default model{size} ({where}) is not prepared")
    return path


def load_plan(s: ModelSpec, max_batch: int = 1) -> tuple[dict[str, Any], str | None]:
    """The backend options for ``s`` (profile already resolved), for batches of up to
    ``max_batch`` frames, and the runtime whose INT8 model it loads (None: the model as it is).
    ConfigError for a precision the backend's runtime cannot take."""
    runtime = QUANT_RUNTIMES.get(s.backend)
    if runtime is None:
        return backend_options(s.precision, s.batch_profile, max_batch), None
    if s.precision not in ("", "fp32", "int8"):
        raise ConfigError(
            f"detector.precision {s.precision!r} is not for backend {s.backend}: use fp32 or int8"
        )
    options = backend_options("", s.batch_profile, max_batch)
    return options, runtime if s.precision == "int8" else None


def on_fp32(model: Path, s: ModelSpec, options: dict[str, Any], exc: Exception) -> Prepared:
    """What to load when ``s``'s INT8 model could not be built: ``model``, with a note."""
    note = f"{exc}; the detector stays on FP32"
    log.warning("%s", note)
    return Prepared(model, s.backend, options, note)


def locate(s: ModelSpec, max_batch: int = 1) -> Prepared:
    """The model, backend and options for ``s`` (profile already resolved), for batches of up
    to ``max_batch`` frames, from the files preparation made, never building anything:
    NotPrepared names what is missing."""
    model = located_model(s)
    options, runtime = load_plan(s, max_batch)
    if runtime is None:
        return Prepared(model, s.backend, options)
    calibration_dir = Path(s.calibration_dir) if s.calibration_dir else None
    try:
        quantized = cached_model(model, runtime=runtime, calibration_dir=calibration_dir)
    except QuantizationFailed as exc:
        return on_fp32(model, s, options, exc)
    if quantized is None:
        where = slot(model, runtime)[0]
        raise NotPrepared(f"the INT8 model of {model.name} ({where}) is not prepared")
    return Prepared(quantized, s.backend, options)


def open_located(s: DetectorSpec, max_batch: int = 1) -> tuple[Detector, str]:
    """The Detector for ``s`` (profile already resolved), for batches of up to ``max_batch``
    frames, from what was prepared ahead (:func:`locate`), and its note: builds nothing."""
    return open_as(s, locate(s, max_batch))


def open_as(s: DetectorSpec, prepared: Prepared) -> tuple[Detector, str]:
    """The Detector for what was ``prepared``, keeping ``s``'s decode options; its note."""
    det = Detector.open(prepared.model, backend=prepared.backend, settings=s, **prepared.options)
    return det, prepared.note


def variant_of(det: Detector) -> str:
    """What a loaded detector runs, as a variant label."""
    size = det.info.input_height if det.info.input_height else NATIVE_IMGSZ
    return f"{det.backend.name}:{det.backend.precision}:{size}"
