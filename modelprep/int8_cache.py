"""Where an INT8 model is cached beside the model it comes from, under which key, and the
lookup serving does: :func:`cached_model` finds what was built ahead, never building it.

Building is :mod:`modelprep.quantize` (``zstack prepare``), which writes each slot and its
sidecar through this module. Nothing here imports a quantizer: serving looks its INT8 model up
without ever loading ONNX Runtime's quantization tool or NNCF (tests/unit/test_imports.py
checks that serving's load path reaches nothing under modelprep/quantize/).

One slot per model and runtime, whose JSON sidecar holds the :class:`QuantKey` (the model's
sha256, the runtime, the quantizer's settings, the input size, the calibration images' digest)
plus the output's sha256::

    <cache_dir>/<model stem>.<runtime>-int8.onnx   (.xml + .bin for openvino)
    <cache_dir>/<model stem>.<runtime>-int8.json
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.util
import json
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from common.errors import ModelError, one_line
from common.files import sha256_file

#: The main file each runtime's quantizer writes.
SUFFIXES: dict[str, str] = {"onnxruntime": ".onnx", "openvino": ".xml"}
#: What each runtime's quantizer (modelprep/quantize/) produces: part of the cache key, so a
#: change here re-quantizes. ONNX Runtime's (ort_int8.py) as it calls ``quantize_static``.
QUANTIZER_SETTINGS: dict[str, dict[str, Any]] = {
    "onnxruntime": {
        "format": "QDQ",
        "activations": "QUInt8",
        "weights": "QInt8",
        "per_channel": True,
        "reduce_range": True,
        "calibration": "MinMax",
    },
    "openvino": {},
}
#: The packages each runtime's quantizer imports: without them it cannot have built a model.
QUANTIZER_NEEDS: dict[str, tuple[str, ...]] = {
    "onnxruntime": ("onnxruntime", "onnx"),
    "openvino": ("nncf", "openvino", "onnx"),
}
#: Bump when anything here changes what a cached INT8 model would be.
FORMAT = 1


class QuantizationFailed(ModelError):
    """The model could not be quantized (or the result does not work); stay on FP32."""


@dataclass(frozen=True, slots=True, kw_only=True)
class QuantKey:
    """Everything a cached INT8 model depends on."""

    model_sha256: str
    runtime: str
    runtime_version: str
    settings: str  # the quantizer's settings, as sorted JSON
    imgsz: tuple[int, int]
    calibration: str  # sha256 over the calibration frames
    format: int = FORMAT

    def to_json(self) -> dict[str, Any]:
        data = dataclasses.asdict(self)
        data["imgsz"] = list(self.imgsz)
        return data


def slot(model: Path, runtime: str, cache_dir: Path | None = None) -> tuple[Path, Path]:
    """``(INT8 model, sidecar)`` paths for ``model`` on ``runtime``."""
    folder = cache_dir if cache_dir is not None else model.parent
    base = f"{model.stem}.{runtime}-int8"
    return folder / (base + SUFFIXES[runtime]), folder / (base + ".json")


def cache_miss(sidecar: Path, out: Path, key: QuantKey) -> str | None:
    """None when ``out`` is a valid build for ``key``, else why it must be rebuilt."""
    try:
        stored = json.loads(sidecar.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return "no INT8 model cached yet"
    except (OSError, ValueError) as exc:
        return f"unreadable sidecar ({one_line(exc)})"
    if not isinstance(stored, dict) or not isinstance(stored.get("key"), dict):
        return "malformed sidecar"
    changed = [k for k, v in key.to_json().items() if stored["key"].get(k) != v]
    if changed:
        return f"{', '.join(changed)} changed"
    if "failed" in stored:
        return f"the last build failed: {stored['failed']}"
    try:
        if sha256_file(out) != stored.get("sha256"):
            return "the INT8 model file changed on disk"
    except OSError:
        return "the INT8 model file is missing"
    return None


def input_hw(model: Path) -> tuple[int, int]:
    """The fixed (height, width) of an NCHW model input; QuantizationFailed when not fixed."""
    import onnx

    graph = onnx.load(str(model), load_external_data=False).graph
    initializers = {init.name for init in graph.initializer}
    (image,) = [i for i in graph.input if i.name not in initializers][:1] or [None]
    dims = [d.dim_value for d in image.type.tensor_type.shape.dim] if image else []
    if len(dims) != 4 or min(dims[2:]) < 1:
        raise QuantizationFailed(f"{model.name}: INT8 needs a fixed NCHW input size, got {dims}")
    return dims[2], dims[3]


def calibration_frames(
    hw: tuple[int, int], calibration_dir: Path | None
) -> tuple[list[npt.NDArray[np.float32]], str]:
    """The preprocessed calibration frames and their digest."""
    from modelprep.calibration import calibration_frames, calibration_images, calibration_photos

    extra = calibration_images(calibration_dir) if calibration_dir is not None else []
    photos = [image for _, image in calibration_photos(extra)]
    frames = calibration_frames(photos, *hw)
    digest = hashlib.sha256()
    for frame in frames:
        digest.update(frame.tobytes())
    return frames, digest.hexdigest()


def check_quantizer(runtime: str) -> None:
    """QuantizationFailed (one line) when ``runtime`` has no quantizer, or its packages are
    not installed here; found without importing them."""
    if runtime not in QUANTIZER_NEEDS:
        raise QuantizationFailed(f"no INT8 quantizer for runtime {runtime!r}")
    for package in QUANTIZER_NEEDS[runtime]:
        if importlib.util.find_spec(package) is None:
            raise QuantizationFailed(
                f"the {runtime} quantizer is not installed: No module named {package!r}"
            )


def _version(runtime: str) -> str:
    try:
        return metadata.version(runtime)
    except metadata.PackageNotFoundError:
        return "unknown"


def cache_key(
    model: Path, runtime: str, calibration_dir: Path | None
) -> tuple[QuantKey, list[npt.NDArray[np.float32]]]:
    """The cache key of ``model``'s INT8 build for ``runtime``, and the calibration frames."""
    hw = input_hw(model)
    frames, digest = calibration_frames(hw, calibration_dir)
    key = QuantKey(
        model_sha256=sha256_file(model),
        runtime=runtime,
        runtime_version=_version(runtime),
        settings=json.dumps(QUANTIZER_SETTINGS[runtime], sort_keys=True),
        imgsz=hw,
        calibration=digest,
    )
    return key, frames


def cached_model(
    model: Path,
    *,
    runtime: str,
    calibration_dir: Path | None = None,
    cache_dir: Path | None = None,
) -> Path | None:
    """The INT8 version of ``model`` for ``runtime`` as built ahead
    (:func:`modelprep.quantize.quantized_model`), never building it: None when it was not
    built for these settings; QuantizationFailed (its one line) when its runtime's quantizer
    is missing or its last build failed."""
    check_quantizer(runtime)
    key, _ = cache_key(model, runtime, calibration_dir)
    out, sidecar = slot(model, runtime, cache_dir)
    why = cache_miss(sidecar, out, key)
    if why is None:
        return out
    if why.startswith("the last build failed: "):
        raise QuantizationFailed(why.removeprefix("the last build failed: "))
    return None
