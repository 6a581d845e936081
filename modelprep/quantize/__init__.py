"""INT8 models by post-training static quantization, cached beside the model they come from.

``quantized_model(model, runtime=...)`` returns the INT8 model for ``model``, building it the
first time with the runtime's own tool (a module per runtime in :data:`RUNTIMES`, imported
lazily, each with ``quantize(model, out, frames, *, keep_float)``): calibrated on real photos
that ship offline (:func:`~modelprep.calibration.calibration_photos`) plus the user's own
frames, preprocessed exactly as the detector does, with the detection head and its decode
(:func:`head_nodes`) kept in float.

The cache (modelprep/int8_cache.py) follows the TensorRT engine cache: one slot per model and
runtime, whose JSON sidecar holds the :class:`QuantKey` plus the output's sha256. A different
key, or a file that no longer hashes right, rebuilds the slot and says why.

A quantization that raises, or whose model fails the caller's ``check`` (it finds nothing
where FP32 finds objects, say), raises :class:`QuantizationFailed` with one line, and its
sidecar records the failure under the key; the caller then stays on FP32. A build runs ahead
of serving (``zstack prepare``); what a service asks is :func:`modelprep.int8_cache.cached_model`
(re-exported here for the tools): the INT8 model built for this key, None when none was,
QuantizationFailed when the last build failed. Serving never imports this package.
"""

from __future__ import annotations

import importlib
import json
import os
import shutil
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from common.errors import one_line
from common.files import atomic_write_bytes, sha256_file, temporary_folder
from common.lifecycle import Progress, print_progress
from modelprep.int8_cache import (
    QuantizationFailed,
    QuantKey,
    cache_key,
    cache_miss,
    cached_model,
    slot,
)
from modelprep.quantize.head import head_nodes

__all__ = [
    "RUNTIMES",
    "Check",
    "QuantKey",
    "QuantizationFailed",
    "cached_model",
    "head_nodes",
    "quantized_model",
    "remove_orphan_scratch",
    "slot",
]

#: Runtime -> the module (in this package) that quantizes for it.
RUNTIMES: dict[str, str] = {"onnxruntime": "ort_int8", "openvino": "nncf_int8"}
PROGRESS_EVERY = 6  # frames between progress lines while calibrating

#: Returns None when the quantized model at that path is good, else why it is not.
Check = Callable[[Path], str | None]


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


def _runtime_module(runtime: str) -> Any:
    module = RUNTIMES.get(runtime)
    if module is None:
        raise QuantizationFailed(f"no INT8 quantizer for runtime {runtime!r}")
    try:
        return importlib.import_module(f"{__name__}.{module}")
    except ImportError as exc:
        raise QuantizationFailed(f"the {runtime} quantizer is not installed: {exc}") from exc


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
    key, frames = cache_key(model, runtime, calibration_dir)
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
