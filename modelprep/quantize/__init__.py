"""INT8 models by post-training static quantization, cached beside the model they come from.

``quantized_model(model, runtime=...)`` returns the INT8 model for ``model``, building it the
first time with the runtime's own tool (a module per runtime in :data:`RUNTIMES`, imported
lazily, each with ``quantize(model, out, frames, *, keep_float)``): calibrated on real photos
that ship offline (:func:`~modelprep.quantize.calibration.calibration_photos`) plus the
user's own frames, preprocessed exactly as the detector does, with the detection head and its
decode (:func:`head_nodes`) kept in float.

The cache follows the TensorRT engine cache: one slot per model and runtime, whose JSON
sidecar holds the :class:`QuantKey` (the model's sha256, the runtime, the quantizer's settings,
the input size, the calibration images' digest) plus the output's sha256. A different key, or a
file that no longer hashes right, rebuilds the slot and says why::

    <cache_dir>/<model stem>.<runtime>-int8.onnx   (.xml + .bin for openvino)
    <cache_dir>/<model stem>.<runtime>-int8.json

A quantization that raises, or whose model fails the caller's ``check`` (it finds nothing
where FP32 finds objects, say), raises :class:`QuantizationFailed` with one line, and its
sidecar records the failure under the key; the caller then stays on FP32. A build runs ahead
of serving (``zstack prepare``); :func:`cached_model` is what a service asks: the INT8 model
built for this key, None when none was, QuantizationFailed when the last build failed.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import os
import shutil
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from common.errors import ModelError, one_line
from common.files import atomic_write_bytes, sha256_file, temporary_folder
from common.lifecycle import Progress, print_progress
from modelprep.quantize.head import head_nodes

#: Runtime -> the module (in this package) that quantizes for it.
RUNTIMES: dict[str, str] = {"onnxruntime": "ort_int8", "openvino": "nncf_int8"}
#: The main file each runtime's module writes.
SUFFIXES: dict[str, str] = {"onnxruntime": ".onnx", "openvino": ".xml"}
#: Bump when anything here changes what a cached INT8 model would be.
FORMAT = 1
PROGRESS_EVERY = 6  # frames between progress lines while calibrating

#: Returns None when the quantized model at that path is good, else why it is not.
Check = Callable[[Path], str | None]


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
    """The fixed (height, width) of an NCHW model input; ModelError when not fixed."""
    import onnx

    graph = onnx.load(str(model), load_external_data=False).graph
    initializers = {init.name for init in graph.initializer}
    (image,) = [i for i in graph.input if i.name not in initializers][:1] or [None]
    dims = [d.dim_value for d in image.type.tensor_type.shape.dim] if image else []
    if len(dims) != 4 or min(dims[2:]) < 1:
        raise QuantizationFailed(f"{model.name}: INT8 needs a fixed NCHW input size, got {dims}")
    return dims[2], dims[3]


class _Reporting(Sequence[npt.NDArray[np.float32]]):
    """The frames, saying every few frames how far the calibration has come."""

    def __init__(self, frames: list[npt.NDArray[np.float32]], progress: Progress) -> None:
        self._frames, self._progress, self._seen = frames, progress, 0

    def __len__(self) -> int:
        return len(self._frames)

    def __getitem__(self, index: Any) -> Any:
        if isinstance(index, int) and index >= self._seen:
            self._seen = index + 1
            if self._seen % PROGRESS_EVERY == 0 or self._seen == len(self._frames):
                self._progress(f"calibrating: frame {self._seen}/{len(self._frames)}")
        return self._frames[index]

    def __iter__(self) -> Iterator[npt.NDArray[np.float32]]:
        return (self[i] for i in range(len(self)))


def _frames(
    hw: tuple[int, int], calibration_dir: Path | None
) -> tuple[list[npt.NDArray[np.float32]], str]:
    """The preprocessed calibration frames and their digest."""
    import hashlib

    from modelprep.quantize.calibration import (
        calibration_frames,
        calibration_images,
        calibration_photos,
    )

    extra = calibration_images(calibration_dir) if calibration_dir is not None else []
    photos = [image for _, image in calibration_photos(extra)]
    frames = calibration_frames(photos, *hw)
    digest = hashlib.sha256()
    for frame in frames:
        digest.update(frame.tobytes())
    return frames, digest.hexdigest()


def _runtime_module(runtime: str) -> Any:
    module = RUNTIMES.get(runtime)
    if module is None:
        raise QuantizationFailed(f"no INT8 quantizer for runtime {runtime!r}")
    try:
        return importlib.import_module(f"{__name__}.{module}")
    except ImportError as exc:
        raise QuantizationFailed(f"the {runtime} quantizer is not installed: {exc}") from exc


def _version(runtime: str) -> str:
    try:
        return metadata.version(runtime)
    except metadata.PackageNotFoundError:
        return "unknown"


def _key(
    module: Any, model: Path, runtime: str, calibration_dir: Path | None
) -> tuple[QuantKey, list[npt.NDArray[np.float32]]]:
    """The cache key of ``model``'s INT8 build for ``runtime``, and the calibration frames."""
    hw = input_hw(model)
    frames, digest = _frames(hw, calibration_dir)
    settings = json.dumps(getattr(module, "SETTINGS", {}), sort_keys=True)
    key = QuantKey(
        model_sha256=sha256_file(model),
        runtime=runtime,
        runtime_version=_version(runtime),
        settings=settings,
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
    """The INT8 version of ``model`` for ``runtime`` as built ahead (:func:`quantized_model`),
    never building it: None when it was not built for these settings; QuantizationFailed (its
    one line) when its runtime's quantizer is missing or its last build failed."""
    module = _runtime_module(runtime)
    key, _ = _key(module, model, runtime, calibration_dir)
    out, sidecar = slot(model, runtime, cache_dir)
    why = cache_miss(sidecar, out, key)
    if why is None:
        return out
    if why.startswith("the last build failed: "):
        raise QuantizationFailed(why.removeprefix("the last build failed: "))
    return None


def quantized_model(
    model: Path,
    *,
    runtime: str,
    calibration_dir: Path | None = None,
    cache_dir: Path | None = None,
    check: Check | None = None,
    progress: Progress = print_progress,
) -> Path:
    """The INT8 version of ``model`` for ``runtime``, from the cache or built now.

    Raises QuantizationFailed (one line) when it cannot be built or fails ``check``, and
    ConfigError for a bad ``calibration_dir``.
    """
    module = _runtime_module(runtime)
    key, frames = _key(module, model, runtime, calibration_dir)
    out, sidecar = slot(model, runtime, cache_dir)
    why = cache_miss(sidecar, out, key)
    if why is None:
        progress(f"INT8 cache hit: {out}")
        return out
    progress(
        f"INT8 cache miss ({why}): quantizing {model.name} for {runtime} on {len(frames)} frames"
    )
    try:
        _build(module, model, out, _Reporting(frames, progress), head_nodes(model))
        reason = check(out) if check is not None else None
        if reason is not None:
            raise QuantizationFailed(f"INT8 {model.name} for {runtime} is unusable: {reason}")
    except QuantizationFailed as exc:
        # recorded, so that a service loading what was prepared knows to stay on FP32
        failed = {"key": key.to_json(), "failed": str(exc)}
        atomic_write_bytes(sidecar, json.dumps(failed, indent=2).encode())
        raise
    record = {"key": key.to_json(), "sha256": sha256_file(out)}
    atomic_write_bytes(sidecar, json.dumps(record, indent=2).encode())
    progress(f"wrote {out}")
    return out


SCRATCH_PREFIX = ".int8-"


def remove_orphan_scratch(folder: Path) -> list[Path]:
    """Remove the scratch folders of quantizations whose process is gone; return them."""
    removed = []
    for scratch in folder.glob(f"{SCRATCH_PREFIX}*"):
        pid = scratch.name.removeprefix(SCRATCH_PREFIX).split("-", 1)[0]
        if not scratch.is_dir() or (pid.isdigit() and _alive(int(pid))):
            continue
        shutil.rmtree(scratch, ignore_errors=True)
        removed.append(scratch)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process: alive
    return True


def _build(
    module: Any, model: Path, out: Path, frames: Sequence[npt.NDArray[np.float32]], keep: list[str]
) -> None:
    """Quantize into a scratch folder, then move every file it wrote beside ``out``.

    The folder is named after this process (``.int8-<pid>-...``): a quantization stopped by
    SIGKILL cannot remove its own, so each build first removes those of processes that are
    gone (a stop by SIGINT or SIGTERM removes its own on the way out).
    """
    out.parent.mkdir(parents=True, exist_ok=True)
    remove_orphan_scratch(out.parent)
    with temporary_folder(out.parent, f"{SCRATCH_PREFIX}{os.getpid()}-") as tmp:
        scratch = Path(tmp) / out.name
        try:
            module.quantize(model, scratch, frames, keep_float=keep)
        except Exception as exc:  # any failure of a third-party tool: one line, stay on FP32
            raise QuantizationFailed(f"cannot quantize {model.name}: {one_line(exc)}") from exc
        if not scratch.is_file():
            raise QuantizationFailed(f"the quantizer wrote no {scratch.name}")
        for written in sorted(Path(tmp).iterdir()):
            if written.is_file() and written.name.startswith(out.stem):
                os.replace(written, out.parent / written.name)
            else:
                shutil.rmtree(written, ignore_errors=True)
