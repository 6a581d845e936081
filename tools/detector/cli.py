"""What the detector's commands do: ``detect``, ``benchmark``, ``prepare``, ``fetch-model``,
``fast-profile`` and ``export`` (their command line is tools/detector/__main__.py). Each takes
typed values and returns an exit code.

Exit codes: 0 success; 1 one or more images could not be read or written (the others were still
processed); 2 bad arguments or settings, or a video or camera device that cannot be opened or
gives not one frame; 3 a bad model (not a model, unknown output family,
fetch failure); 4 a backend this machine lacks; 130 interrupted. Errors are one line on stderr.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
import numpy.typing as npt

from common.annotate import annotate
from common.errors import ConfigError, ImageError
from common.images import Image, list_images, load_image, load_sample
from common.lifecycle import EXIT_FAILED, EXIT_OK, print_progress
from modelprep.files import ensure_default_model
from perception import DetectionResult, Detector, sized_model
from services.camera import CaptureSource, is_stream, open_stream
from services.detector.contract import DetectorSettings
from tools.detector.device import backend_for
from tools.detector.progress import ProgressBar
from tools.detector.results import result_json, result_text
from tools.detector.video import detect_stream

if TYPE_CHECKING:
    from tools.benchmarks.detector import BenchmarkOptions

#: What ``detect`` looks at when given no PATH, as ``yolo predict`` has its bundled images: a
#: scikit-image photo, in the camera's own ``sample:<name>`` form (common/images.py SAMPLES).
SAMPLE_PREFIX = "sample:"
DEFAULT_SAMPLE = f"{SAMPLE_PREFIX}chelsea"
# The stack's shared exit codes (common/lifecycle.py); a failed image is the generic failure.
EXIT_IMAGE_FAILED = EXIT_FAILED


def print_error(message: str) -> None:
    """One error line, as every detector command writes it."""
    print(f"error: {message}", file=sys.stderr)


def _resolve_model(model: str | None, imgsz: int = 0) -> Path:
    """The ``--model`` path, or the default model, fetched first if it is not there yet;
    ``imgsz``: at that input size (the default model is rebuilt for it; another model must
    have it already)."""
    if imgsz:
        return sized_model(DetectorSettings(model=model or "", imgsz=imgsz), print_progress)
    if model is not None:
        return Path(model)
    return ensure_default_model(progress=print_progress)


def _parse_classes(raw: str | None) -> tuple[str, ...] | None:
    if raw is None:
        return None
    names = tuple(name.strip() for name in raw.split(",") if name.strip())
    if not names:
        raise ConfigError("--classes needs at least one class name, e.g. --classes person,cup")
    return names


def _show_backend_log() -> None:
    """Show the backends' INFO lines (auto's choice, engine cache and build progress).

    Only on this logger: ``serve`` configures the root logger itself, later.
    """
    logger = logging.getLogger("runtimes")
    if not logger.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)
        logger.propagate = False


# --- detect -------------------------------------------------------------------------------------


def _save_annotated(
    save_dir: Path, name: str, image: npt.NDArray[np.uint8], result: DetectionResult
) -> None:
    target = save_dir / name
    drawn = annotate(image, result.boxes, result.class_names)
    ok, encoded = cv2.imencode(target.suffix or ".png", drawn)
    if not ok:
        raise ImageError(f"{target}: cannot encode the annotated image")
    try:
        encoded.tofile(target)
    except OSError as exc:
        raise ImageError(f"{target}: cannot write ({exc.strerror or exc})") from exc


@dataclass(frozen=True, slots=True)
class SamplePhoto:
    """A bundled photo named ``sample:<name>``: its name and its BGR pixels."""

    name: str
    image: Image

    @classmethod
    def open(cls, spec: str) -> SamplePhoto:
        """Load ``spec``'s photo now (an unknown name is one line, before the model loads) and
        say which on stderr: with no PATH the user did not name it."""
        name = spec.removeprefix(SAMPLE_PREFIX)
        photo = cls(name=name, image=load_sample(name))
        print_progress(f"detect: {spec}: scikit-image's bundled {name!r} photo")
        return photo


def _detect_image(
    det: Detector, item: Path | SamplePhoto, *, as_json: bool, save_dir: Path | None
) -> bool:
    """Detect on one image file or sample photo and print the result; False (after one error
    line) when the image cannot be read or its annotated copy cannot be written."""
    try:
        if isinstance(item, Path):
            label, image, save_name = str(item), load_image(item), item.name
        else:
            label, image = f"{SAMPLE_PREFIX}{item.name}", item.image
            save_name = f"{item.name}.png"
        result = det.detect(image)
        print(result_json(label, result) if as_json else result_text(label, result))
        if save_dir is not None:
            _save_annotated(save_dir, save_name, image, result)
    except ImageError as exc:
        print_error(str(exc))
        return False
    return True


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectOptions:
    """What ``detect`` was asked: its inputs (empty: :data:`DEFAULT_SAMPLE`), the model and
    where it runs, the thresholds, and the output."""

    paths: tuple[str, ...]
    model: str | None
    backend: str | None
    device: str | None
    imgsz: int
    conf: float
    iou: float
    max_det: int
    classes: str | None  # comma-separated class names, checked by run_detect
    as_json: bool
    save_dir: str | None


def run_detect(options: DetectOptions) -> int:
    """Detect objects in images, folders of images, sample photos, videos and camera devices,
    in order; with no PATH, in the bundled sample photo :data:`DEFAULT_SAMPLE`.

    Bad images are reported and skipped (exit 1 at the end). A video or device that cannot be
    opened, or that gives not one frame, stops with one line (exit 2).
    """
    settings = DetectorSettings(
        conf=options.conf,
        iou=options.iou,
        max_det=options.max_det,
        classes=_parse_classes(options.classes) or (),
    )
    save_dir = Path(options.save_dir) if options.save_dir else None
    with contextlib.ExitStack() as opened:
        # Samples, videos and devices are opened before the model loads: a missing one is one
        # line, now.
        inputs: list[Path | SamplePhoto | tuple[str, CaptureSource]] = []
        for spec in options.paths or [DEFAULT_SAMPLE]:
            if spec.startswith(SAMPLE_PREFIX):
                inputs.append(SamplePhoto.open(spec))
            elif is_stream(spec):
                source = open_stream(spec)
                opened.callback(source.close)
                inputs.append((spec, source))
            else:
                inputs.extend(list_images([spec]))
        if not inputs:
            raise ImageError(f"no images found in {' '.join(options.paths)}")
        if save_dir is not None:
            save_dir.mkdir(parents=True, exist_ok=True)
        backend, backend_options = backend_for(options.backend, options.device)
        _show_backend_log()
        det = opened.enter_context(
            Detector.open(
                _resolve_model(options.model, options.imgsz),
                backend=backend,
                settings=settings,
                **backend_options,
            )
        )
        images = [item for item in inputs if isinstance(item, Path | SamplePhoto)]
        bar = ProgressBar("images", len(images), unit="images") if len(images) > 1 else None
        failed = 0
        for item in inputs:
            if isinstance(item, Path | SamplePhoto):
                failed += not _detect_image(det, item, as_json=options.as_json, save_dir=save_dir)
                if bar is not None:
                    bar.advance()
            else:
                detect_stream(*item, det, as_json=options.as_json, save_dir=save_dir)
        if bar is not None:
            bar.finish()
    if failed and failed == len(images):
        print_error(f"none of the {failed} image(s) could be read")
    elif failed:
        print_error(f"{failed} of {len(images)} image(s) failed")
    return EXIT_IMAGE_FAILED if failed else EXIT_OK


# --- benchmark (tools/benchmarks/detector.py) ----------------------------------------------------


def run_benchmark(options: BenchmarkOptions) -> int:
    """Time each stage on each backend and score their agreement (tools/benchmarks/detector.py)."""
    from tools.benchmarks import detector as bench

    _show_backend_log()
    return bench.run(options, _resolve_model)


# --- export -------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class ExportOptions:
    """What ``export`` was asked: the engine kind, the model, and how to build the engine."""

    backend: str
    model: str | None
    precision: str
    calib: str | None  # folder of calibration images (int8)
    batch: int  # the largest batch served: the profile is 1/batch/batch
    workspace_gb: float
    cache_dir: str | None


def run_export(options: ExportOptions) -> int:
    """Build (or reuse) and cache an engine for ``options.backend``, printing the engine's
    path."""
    from runtimes import import_backend

    module = import_backend(options.backend)  # BackendUnavailable here on a machine without it
    model = _resolve_model(options.model)
    path = module.export_engine(
        model,
        print_progress,
        precision=options.precision,
        batch_profile=(1, options.batch, options.batch),
        calib_dir=Path(options.calib) if options.calib else None,
        cache_dir=Path(options.cache_dir) if options.cache_dir else None,
        workspace_gb=options.workspace_gb,
    )
    print(path)
    return EXIT_OK


# --- prepare, fetch-model and fast-profile ------------------------------------------------------


def run_prepare(config_path: str | None, overrides: dict[str, Any]) -> int:
    """Prepare every model file the stack config (with ``overrides`` of detector settings)
    needs, ahead of serving: the default model fetched and converted, rebuilt at the input
    size, quantized to INT8, the fast profile measured and its choice prepared. Prints the path
    of the model the detector will load; progress on stderr."""
    import dataclasses

    from perception import prepare_for
    from stack.config_file import load_config
    from tools.detector.fast_profile import measure

    config = load_config(config_path)
    if "detector" not in config.supervisor.services:
        print_progress("prepare: the stack runs no detector: nothing to prepare")
        return EXIT_OK
    settings = dataclasses.replace(config.detector, **overrides)
    prepared, _ = prepare_for(settings, print_progress, measure=measure)
    if prepared.note:
        print_progress(f"prepare: {prepared.note}")
    print(prepared.model)
    return EXIT_OK


def run_fetch_model(models_dir: str | None) -> int:
    """Fetch and convert the default model if needed, and print its path."""
    print(ensure_default_model(Path(models_dir) if models_dir else None, progress=print_progress))
    return EXIT_OK


def _measure_fast(settings: DetectorSettings) -> str:
    """Measure (or read from the cache) the fast profile's choice; its variant's label."""
    from perception import choose_fast
    from tools.detector.fast_profile import measure

    variant, why = choose_fast(settings, print_progress, measure=measure)
    print_progress(why)
    return variant.label


def run_fast_profile(config_path: str | None) -> int:
    """Measure the CPU variants once, cache the fast profile's choice, print it."""
    from stack.config_file import load_config

    config = load_config(config_path)
    print(_measure_fast(config.detector))
    return EXIT_OK
