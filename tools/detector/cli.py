"""Command line of the detector: ``detect``, ``benchmark``, ``fetch-model`` and ``export``.

Each subcommand is registered by one function in :data:`SUBCOMMANDS`; a new one (``serve``)
adds its register function there. Handlers take the parsed arguments and return an exit code.

Exit codes: 0 success; 1 one or more images could not be read or written (the others were still
processed); 2 bad arguments or settings, or a video or camera device that cannot be opened or
gives not one frame; 3 a bad model (not a model, unknown output family,
fetch failure); 4 a backend this machine lacks; 130 interrupted. Errors are one line on stderr.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from common.annotate import annotate
from common.cli import program, with_default
from common.errors import ConfigError, ImageError, StackError
from common.images import SAMPLES, Image, list_images, load_image, load_sample
from common.lifecycle import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, exit_code, print_progress
from common.settings import DetectorSettings
from modelprep.files import ensure_default_model
from runtimes import BACKEND_CHOICES
from services.camera import CaptureSource, is_stream, open_stream
from services.detector.pipeline import Detector
from services.detector.types import DetectionResult
from services.detector.variants import sized_model
from tools.detector.device import backend_for
from tools.detector.progress import ProgressBar
from tools.detector.results import result_json, result_text
from tools.detector.video import detect_stream

#: What ``detect`` looks at when given no PATH, as ``yolo predict`` has its bundled images: a
#: scikit-image photo, in the camera's own ``sample:<name>`` form (common/images.py SAMPLES).
SAMPLE_PREFIX = "sample:"
DEFAULT_SAMPLE = f"{SAMPLE_PREFIX}chelsea"
# The stack's shared exit codes (common/lifecycle.py); a failed image is the generic failure.
EXIT_IMAGE_FAILED = EXIT_FAILED
PROG = "python -m tools.detector"
#: The thresholds' defaults: those of the settings, stated once there.
_DEFAULTS = DetectorSettings()


def _error(message: str) -> None:
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


def _add_model_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--model", help="ONNX model (default: the YOLOv5s COCO model, fetched)")
    parser.add_argument(
        "--backend", default="onnx", help=f"one of: {', '.join(BACKEND_CHOICES)} (default onnx)"
    )


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
        _error(str(exc))
        return False
    return True


def run_detect(args: argparse.Namespace) -> int:
    """Detect objects in images, folders of images, sample photos, videos and camera devices,
    in order; with no PATH, in the bundled sample photo :data:`DEFAULT_SAMPLE`.

    Bad images are reported and skipped (exit 1 at the end). A video or device that cannot be
    opened, or that gives not one frame, stops with one line (exit 2).
    """
    settings = DetectorSettings(
        conf=args.conf,
        iou=args.iou,
        max_det=args.max_det,
        classes=_parse_classes(args.classes) or (),
    )
    save_dir = Path(args.save_dir) if args.save_dir else None
    with contextlib.ExitStack() as opened:
        # Samples, videos and devices are opened before the model loads: a missing one is one
        # line, now.
        inputs: list[Path | SamplePhoto | tuple[str, CaptureSource]] = []
        for spec in args.paths or [DEFAULT_SAMPLE]:
            if spec.startswith(SAMPLE_PREFIX):
                inputs.append(SamplePhoto.open(spec))
            elif is_stream(spec):
                source = open_stream(spec)
                opened.callback(source.close)
                inputs.append((spec, source))
            else:
                inputs.extend(list_images([spec]))
        if not inputs:
            raise ImageError(f"no images found in {' '.join(args.paths)}")
        if save_dir is not None:
            save_dir.mkdir(parents=True, exist_ok=True)
        backend, options = backend_for(args.backend, args.device)
        _show_backend_log()
        det = opened.enter_context(
            Detector.open(
                _resolve_model(args.model, args.imgsz),
                backend=backend,
                settings=settings,
                **options,
            )
        )
        images = [item for item in inputs if isinstance(item, Path | SamplePhoto)]
        bar = ProgressBar("images", len(images), unit="images") if len(images) > 1 else None
        failed = 0
        for item in inputs:
            if isinstance(item, Path | SamplePhoto):
                failed += not _detect_image(det, item, as_json=args.json, save_dir=save_dir)
                if bar is not None:
                    bar.advance()
            else:
                detect_stream(*item, det, as_json=args.json, save_dir=save_dir)
        if bar is not None:
            bar.finish()
    if failed and failed == len(images):
        _error(f"none of the {failed} image(s) could be read")
    elif failed:
        _error(f"{failed} of {len(images)} image(s) failed")
    return EXIT_IMAGE_FAILED if failed else EXIT_OK


def _add_detect(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "detect",
        prog=program(PROG, "detect"),
        help="detect objects in images, folders, videos, a camera device or a bundled photo",
    )
    p.add_argument(
        "paths",
        nargs="*",
        metavar="PATH",
        help="image file, folder of images, video file, device:N, /dev/videoN, a stream URL "
        "(rtsp://, http://, ...) or a bundled photo sample:NAME "
        f"({', '.join(SAMPLES)}); default: {DEFAULT_SAMPLE}",
    )
    p.add_argument("--model", help="ONNX model (default: the YOLOv5s COCO model, fetched)")
    p.add_argument(
        "--backend",  # checked when the backend opens: one line, not argparse's usage block
        help=f"{', '.join(BACKEND_CHOICES)} (default: onnx; cuda with a GPU --device)",
    )
    p.add_argument("--device", help="cpu, N, cuda or cuda:N (as yolo's --device)")
    p.add_argument(
        "--imgsz",
        type=int,
        default=0,
        help="input size, a multiple of 32 (default: the model's own; the default model is "
        "rebuilt for it)",
    )
    p.add_argument("--conf", type=float, default=_DEFAULTS.conf, help="minimum score, 0..1")
    p.add_argument("--iou", type=float, default=_DEFAULTS.iou, help="NMS IoU threshold, 0..1")
    p.add_argument("--max-det", type=int, default=_DEFAULTS.max_det, help="detections per image")
    p.add_argument("--classes", help="comma-separated class names to keep, e.g. person,cup")
    p.add_argument(
        "--json", action="store_true", help="one JSON object per image or frame per line"
    )
    p.add_argument(
        "--save-dir",
        help="write annotated copies of the images, and of videos (plus their .jsonl), here",
    )
    p.set_defaults(handler=run_detect)


# --- benchmark (tools/benchmarks/detector.py) ----------------------------------------------------


def run_benchmark(args: argparse.Namespace) -> int:
    """Time each stage on each ``--backend`` and score their agreement (see bench.py)."""
    from tools.benchmarks import detector as bench

    _show_backend_log()
    return bench.run(args, _resolve_model)


def _add_benchmark(subparsers: Any) -> None:
    from tools.benchmarks import detector as bench

    p = subparsers.add_parser(
        "benchmark", prog=program(PROG, "benchmark"), help="time each stage on one or more backends"
    )
    p.add_argument("--model", help="ONNX model (default: the YOLOv5s COCO model, fetched)")
    bench.add_arguments(p)
    p.set_defaults(handler=run_benchmark)


# --- export -------------------------------------------------------------------------------------


def run_export(args: argparse.Namespace) -> int:
    """Build (or reuse) and cache an engine for ``--backend``, printing the engine's path."""
    from runtimes import import_backend

    module = import_backend(args.backend)  # BackendUnavailable here on a machine without it
    model = _resolve_model(args.model)
    path = module.export_engine(
        model,
        print_progress,
        precision=args.precision,
        batch_profile=(1, args.batch, args.batch),
        calib_dir=Path(args.calib) if args.calib else None,
        cache_dir=Path(args.cache_dir) if args.cache_dir else None,
        workspace_gb=args.workspace_gb,
    )
    print(path)
    return EXIT_OK


def _add_export(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "export", prog=program(PROG, "export"), help="build and cache a TensorRT engine for a model"
    )
    p.add_argument("--backend", choices=["tensorrt"], default="tensorrt", help="engine kind")
    p.add_argument("--model", help="ONNX model (default: the YOLOv5s COCO model, fetched)")
    p.add_argument("--precision", choices=["fp32", "fp16", "int8"], default="fp16")
    p.add_argument("--calib", help="folder of calibration images (needed to build int8)")
    p.add_argument("--batch", type=int, default=1, help="largest batch served (profile 1/N/N)")
    p.add_argument("--workspace-gb", type=float, default=4.0, help="builder scratch memory")
    p.add_argument("--cache-dir", help="engine cache folder (default: <models>/engines)")
    p.set_defaults(handler=run_export)


# --- fetch-model --------------------------------------------------------------------------------


def run_fetch_model(args: argparse.Namespace) -> int:
    """Fetch and convert the default model if needed, and print its path. With ``--config``,
    only when that stack runs a detector on the default model, and then also measure the fast
    profile if the config asks for it (what ``make run`` asks before it starts the stack)."""
    if args.config:
        from common.config_file import load_config

        config = load_config(args.config)
        if "detector" not in config.supervisor.services:
            print_progress("fetch-model: the stack runs no detector: nothing to fetch")
            return EXIT_OK
        if not config.detector.model:
            print(ensure_default_model(progress=print_progress))
        else:
            print_progress(
                f"fetch-model: detector.model is {config.detector.model}: nothing to fetch"
            )
        if config.detector.profile == "fast":
            _measure_fast(config.detector)
        return EXIT_OK
    models_dir = Path(args.models_dir) if args.models_dir else None
    print(ensure_default_model(models_dir, progress=print_progress))
    return EXIT_OK


def _measure_fast(settings: DetectorSettings) -> str:
    """Measure (or read from the cache) the fast profile's choice; its variant's label."""
    from services.detector.fast_profile import choose_fast
    from tools.detector.fast_profile import measure

    variant, why = choose_fast(settings, print_progress, measure=measure)
    print_progress(why)
    return variant.label


def run_fast_profile(args: argparse.Namespace) -> int:
    """Measure the CPU variants once, cache the fast profile's choice, print it."""
    from common.config_file import load_config

    config = load_config(args.config)
    print(_measure_fast(config.detector))
    return EXIT_OK


def _add_fast_profile(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "fast-profile",
        prog=program(PROG, "fast-profile"),
        help="measure the CPU variants once and cache the fast profile's choice",
    )
    p.add_argument("--config", help="stack config (default deploy/stack.toml)")
    p.set_defaults(handler=run_fast_profile)


def _add_fetch_model(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "fetch-model", prog=program(PROG, "fetch-model"), help="fetch and convert the default model"
    )
    p.add_argument("--models-dir", help="where to put it (default: the stack's models folder)")
    p.add_argument("--config", help="only if this stack config uses the default model")
    p.set_defaults(handler=run_fetch_model)


#: Subcommand registrations, in help order.
SUBCOMMANDS: list[Callable[[Any], None]] = [
    _add_detect,
    _add_benchmark,
    _add_fetch_model,
    _add_fast_profile,
    _add_export,
]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand in :data:`SUBCOMMANDS`."""
    parser = argparse.ArgumentParser(prog=program(PROG), description="YOLO object detector")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for register in SUBCOMMANDS:
        register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default ``sys.argv[1:]``), run the subcommand, return its exit code."""
    names = ["detect", "benchmark", "fetch-model", "fast-profile", "export"]
    words = sys.argv[1:] if argv is None else argv
    args = build_parser().parse_args(with_default(words, names, "detect"))
    handler: Callable[[argparse.Namespace], int] = args.handler
    try:
        return handler(args)
    except StackError as exc:
        _error(str(exc))
        return exit_code(exc)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
