"""From settings to the model file a backend loads: input size, precision, fast profile.

A *variant* is ``backend:precision:imgsz`` (``onnx:int8:480``). :func:`prepare` turns
DetectorSettings into one, building what it needs: the model at that input size (the default
model is rebuilt for it; a named model must already have it), then, for ``int8`` on a runtime we
quantize for (:data:`QUANT_RUNTIMES`), the INT8 model from :mod:`modelprep.quantize`. An INT8
model that cannot be built leaves the detector on FP32, with one warning line and a ``note``.
That runs ahead of serving (``zstack prepare``). :func:`locate` finds the same files and builds
nothing: what is missing raises :class:`NotPrepared`, one line naming it and what to run.
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
from modelprep.files import (
    NATIVE_IMGSZ,
    current_default_model,
    default_model_path,
    ensure_default_model,
)
from perception.pipeline import Detector
from runtimes.select import backend_options
from services.detector.contract import DetectorSettings

log = logging.getLogger("perception.variants")

#: Backend -> the runtime whose quantizer builds its INT8 model.
QUANT_RUNTIMES = {"onnx": "onnxruntime", "openvino": "openvino"}
#: What a user runs to prepare the models a stack config needs, ahead of serving.
PREPARE_COMMAND = "zstack prepare"


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


def located_model(s: DetectorSettings) -> Path:
    """What :func:`sized_model` returns, never building it: the default model at ``s.imgsz``
    must be there and current (NotPrepared otherwise)."""
    if s.model:
        return sized_model(s)  # the user's own file: nothing is built for it
    path = current_default_model(imgsz=s.imgsz)
    if path is None:
        size = f" at input size {s.imgsz}" if s.imgsz not in (0, NATIVE_IMGSZ) else ""
        where = default_model_path(imgsz=s.imgsz)
        raise NotPrepared(f"the default model{size} ({where}) is not prepared")
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
    batches of up to ``max_batch`` frames, built now where they are missing."""
    return _resolve(s, max_batch, progress)


def locate(s: DetectorSettings, max_batch: int = 1) -> Prepared:
    """What :func:`prepare` returns, from the files it made, never building anything:
    NotPrepared names what is missing."""
    return _resolve(s, max_batch, None)


def _resolve(s: DetectorSettings, max_batch: int, build: Progress | None) -> Prepared:
    """:func:`prepare` with ``build`` (its progress), :func:`locate` without."""
    model = sized_model(s, build) if build is not None else located_model(s)
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
    from modelprep.quantize import QuantizationFailed, cached_model, quantized_model, slot

    calibration_dir = Path(s.calibration_dir) if s.calibration_dir else None
    try:
        if build is not None:
            quantized = quantized_model(
                model,
                runtime=runtime,
                calibration_dir=calibration_dir,
                check=finds_objects(model, s.backend),
                progress=build,
            )
        else:
            found = cached_model(model, runtime=runtime, calibration_dir=calibration_dir)
            if found is None:
                where = slot(model, runtime)[0]
                raise NotPrepared(f"the INT8 model of {model.name} ({where}) is not prepared")
            quantized = found
    except QuantizationFailed as exc:
        note = f"{exc}; the detector stays on FP32"
        log.warning("%s", note)
        return Prepared(model, s.backend, options, note)
    return Prepared(quantized, s.backend, options)


def open_prepared(
    s: DetectorSettings, progress: Progress = print_progress, max_batch: int = 1
) -> tuple[Detector, str]:
    """The Detector for settings ``s`` (profile already resolved), for batches of up to
    ``max_batch`` frames, built first where needed (:func:`prepare`), and its note."""
    return _open(s, prepare(s, progress, max_batch))


def open_located(s: DetectorSettings, max_batch: int = 1) -> tuple[Detector, str]:
    """:func:`open_prepared` from what was prepared ahead (:func:`locate`): builds nothing."""
    return _open(s, locate(s, max_batch))


def _open(s: DetectorSettings, prepared: Prepared) -> tuple[Detector, str]:
    det = Detector.open(prepared.model, backend=prepared.backend, settings=s, **prepared.options)
    return det, prepared.note


def variant_of(det: Detector) -> str:
    """What a loaded detector runs, as a variant label."""
    size = det.info.input_height if det.info.input_height else NATIVE_IMGSZ
    return f"{det.backend.name}:{det.backend.precision}:{size}"
