"""Command line of the detector: ``detect``, ``benchmark`` and ``fetch-model``.

Each subcommand is registered by one function in :data:`SUBCOMMANDS`; a new one (``serve``)
adds its register function there. Handlers take the parsed arguments and return an exit code.

Exit codes: 0 success; 1 one or more images could not be read or written (the others were still
processed); 2 bad arguments or settings; 3 a bad model (not a model, unknown output family,
fetch failure); 4 a backend this machine lacks; 130 interrupted. Errors are one line on stderr.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from common.errors import BackendUnavailable, ConfigError, ImageError, ModelError, StackError
from services.detector.annotate import annotate
from services.detector.backends import BACKENDS
from services.detector.images import list_images, load_image
from services.detector.pipeline import Detector
from services.detector.types import (
    DEFAULT_CONF,
    DEFAULT_IOU,
    DEFAULT_MAX_DET,
    DetectionResult,
    DetectorParams,
)

EXIT_OK = 0
EXIT_IMAGE_FAILED = 1
EXIT_USAGE = 2
EXIT_MODEL = 3
EXIT_BACKEND = 4
EXIT_INTERRUPTED = 130


def _error(message: str) -> None:
    print(f"error: {message}", file=sys.stderr)


def _progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _resolve_model(model: str | None) -> Path:
    """The ``--model`` path, or the default model, fetched first if it is not there yet."""
    if model is not None:
        return Path(model)
    from services.detector.model_store import ensure_default_model  # fetch code: only if needed

    return ensure_default_model(progress=_progress)


def _parse_classes(raw: str | None) -> tuple[str, ...] | None:
    if raw is None:
        return None
    names = tuple(name.strip() for name in raw.split(",") if name.strip())
    if not names:
        raise ConfigError("--classes needs at least one class name, e.g. --classes person,cup")
    return names


def _add_model_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--model", help="ONNX model (default: the YOLOv5s COCO model, fetched)")
    parser.add_argument("--backend", default="onnx", help=f"one of: {', '.join(sorted(BACKENDS))}")


# --- detect -------------------------------------------------------------------------------------


def _result_json(path: Path, result: DetectionResult) -> str:
    detections = [
        {
            "class_id": cid,
            "class_name": name,
            "score": round(score, 4),
            "bbox_xyxy": [round(v, 2) for v in box],
        }
        for cid, name, score, box in zip(
            result.class_ids.tolist(),
            result.class_names,
            result.scores.tolist(),
            result.xyxy.tolist(),
            strict=True,
        )
    ]
    t = result.timing
    return json.dumps(
        {
            "image": str(path),
            "width": result.image_width,
            "height": result.image_height,
            "detections": detections,
            "timing_ms": {
                "preprocess": round(t.preprocess_ms, 3),
                "inference": round(t.inference_ms, 3),
                "postprocess": round(t.postprocess_ms, 3),
            },
        }
    )


def _result_text(path: Path, result: DetectionResult) -> str:
    found = ", ".join(
        f"{name} {score:.2f} [{', '.join(f'{v:.0f}' for v in box)}]"
        for name, score, box in zip(
            result.class_names, result.scores.tolist(), result.xyxy.tolist(), strict=True
        )
    )
    t = result.timing
    return (
        f"{path}: {result.image_width}x{result.image_height}, {len(result)} detection(s)"
        f"{': ' + found if found else ''} (pre {t.preprocess_ms:.1f} ms, "
        f"infer {t.inference_ms:.1f} ms, post {t.postprocess_ms:.1f} ms)"
    )


def _save_annotated(
    save_dir: Path, path: Path, image: npt.NDArray[np.uint8], result: DetectionResult
) -> None:
    target = save_dir / path.name
    ok, encoded = cv2.imencode(target.suffix or ".png", annotate(image, result))
    if not ok:
        raise ImageError(f"{target}: cannot encode the annotated image")
    try:
        encoded.tofile(target)
    except OSError as exc:
        raise ImageError(f"{target}: cannot write ({exc.strerror or exc})") from exc


def run_detect(args: argparse.Namespace) -> int:
    """Detect objects in each image; bad images are reported and skipped (exit 1 at the end)."""
    params = DetectorParams(
        conf=args.conf, iou=args.iou, max_det=args.max_det, classes=_parse_classes(args.classes)
    )
    paths = list_images(args.paths)
    if not paths:
        raise ImageError(f"no images found in {' '.join(args.paths)}")
    save_dir = Path(args.save_dir) if args.save_dir else None
    if save_dir is not None:
        save_dir.mkdir(parents=True, exist_ok=True)
    failed = 0
    with Detector.open(_resolve_model(args.model), backend=args.backend, params=params) as det:
        for path in paths:
            try:
                image = load_image(path)
                result = det.detect(image)
                print(_result_json(path, result) if args.json else _result_text(path, result))
                if save_dir is not None:
                    _save_annotated(save_dir, path, image, result)
            except ImageError as exc:
                _error(str(exc))
                failed += 1
    if failed:
        _error(f"{failed} of {len(paths)} image(s) failed")
    return EXIT_IMAGE_FAILED if failed else EXIT_OK


def _add_detect(subparsers: Any) -> None:
    p = subparsers.add_parser("detect", help="detect objects in images or folders of images")
    p.add_argument("paths", nargs="+", metavar="PATH", help="image file or folder of images")
    _add_model_arguments(p)
    p.add_argument("--conf", type=float, default=DEFAULT_CONF, help="minimum score, 0..1")
    p.add_argument("--iou", type=float, default=DEFAULT_IOU, help="NMS IoU threshold, 0..1")
    p.add_argument("--max-det", type=int, default=DEFAULT_MAX_DET, help="detections per image")
    p.add_argument("--classes", help="comma-separated class names to keep, e.g. person,cup")
    p.add_argument("--json", action="store_true", help="one JSON object per image per line")
    p.add_argument("--save-dir", help="write annotated copies of the images here")
    p.set_defaults(handler=run_detect)


# --- benchmark ----------------------------------------------------------------------------------


def _cpu_model() -> str:
    try:
        cpuinfo = Path("/proc/cpuinfo").read_text()
    except OSError:  # not Linux: platform.processor() is the best we have
        cpuinfo = ""
    for line in cpuinfo.splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor() or "unknown"


def _machine() -> dict[str, Any]:
    return {
        "cpu_model": _cpu_model(),
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
    }


def _percentiles(samples: dict[str, list[float]], q: float) -> dict[str, float]:
    return {k: round(float(np.percentile(v, q)), 3) for k, v in samples.items()}


def _benchmark_image(path: str | None) -> npt.NDArray[np.uint8]:
    if path is not None:
        return load_image(path)
    from skimage import data  # slow import, only for the default image

    return np.ascontiguousarray(data.chelsea()[:, :, ::-1])  # RGB -> BGR


def run_benchmark(args: argparse.Namespace) -> int:
    """Time each stage, interleaving full detect calls with bare backend runs on one input."""
    if args.runs < 1 or args.warmup < 0:
        raise ConfigError(f"--runs must be >= 1 and --warmup >= 0, got {args.runs}, {args.warmup}")
    image = _benchmark_image(args.image)
    model = _resolve_model(args.model)
    stages = ("preprocess", "inference", "postprocess", "total")
    samples: dict[str, list[float]] = {k: [] for k in stages}
    bare: list[float] = []
    with Detector.open(model, backend=args.backend) as det:
        bare_input = det.preprocess([image])[0].copy()  # same tensor the detect call builds

        def timed_detect() -> tuple[DetectionResult, float]:
            t0 = time.perf_counter()
            result = det.detect(image)
            return result, (time.perf_counter() - t0) * 1e3

        def timed_bare() -> float:
            t0 = time.perf_counter()
            det.backend.infer(bare_input)
            return (time.perf_counter() - t0) * 1e3

        for i in range(args.warmup + args.runs):
            # Alternate which goes first so that neither always runs on the warmer cache.
            if i % 2 == 0:
                result, total_ms = timed_detect()
                bare_ms = timed_bare()
            else:
                bare_ms = timed_bare()
                result, total_ms = timed_detect()
            if i < args.warmup:
                continue
            bare.append(bare_ms)
            samples["preprocess"].append(result.timing.preprocess_ms)
            samples["inference"].append(result.timing.inference_ms)
            samples["postprocess"].append(result.timing.postprocess_ms)
            samples["total"].append(total_ms)
        p50 = _percentiles(samples, 50)
        report = {
            "p50_ms": p50,
            "p95_ms": _percentiles(samples, 95),
            "bare_run_p50_ms": round(float(np.median(bare)), 3),
            "ratio_to_bare_run": round(p50["total"] / float(np.median(bare)), 4),
            "pre_post_fraction_of_inference": round(
                (p50["preprocess"] + p50["postprocess"]) / p50["inference"], 4
            ),
            "runs": args.runs,
            "warmup": args.warmup,
            "backend": {
                "name": det.backend.name,
                "device": det.backend.device,
                "precision": det.backend.precision,
                "threads": getattr(det.backend, "threads", None),
            },
            "model": {
                "path": str(model),
                "family": det.info.family.value,
                "input": [det.info.input_height, det.info.input_width],
            },
            "image": {
                "path": args.image or "skimage:chelsea",
                "width": image.shape[1],
                "height": image.shape[0],
            },
            "machine": _machine(),
        }
    if args.json:
        print(json.dumps(report))
    else:
        for key in ("p50_ms", "p95_ms"):
            print(f"{key[:3]}: " + ", ".join(f"{k} {v:.2f} ms" for k, v in report[key].items()))
        print(
            f"bare run p50 {report['bare_run_p50_ms']:.2f} ms; detect/bare "
            f"{report['ratio_to_bare_run']:.3f}; (pre+post)/inference "
            f"{report['pre_post_fraction_of_inference']:.3f}"
        )
    return EXIT_OK


def _add_benchmark(subparsers: Any) -> None:
    p = subparsers.add_parser("benchmark", help="time each stage against a bare backend run")
    _add_model_arguments(p)
    p.add_argument("--runs", type=int, default=50, help="timed runs (default 50)")
    p.add_argument("--warmup", type=int, default=5, help="untimed runs first (default 5)")
    p.add_argument("--image", help="image to time on (default: scikit-image chelsea)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=run_benchmark)


# --- fetch-model --------------------------------------------------------------------------------


def run_fetch_model(args: argparse.Namespace) -> int:
    """Fetch and convert the default model if needed, and print its path."""
    from services.detector.model_store import ensure_default_model

    models_dir = Path(args.models_dir) if args.models_dir else None
    print(ensure_default_model(models_dir, progress=_progress))
    return EXIT_OK


def _add_fetch_model(subparsers: Any) -> None:
    p = subparsers.add_parser("fetch-model", help="fetch and convert the default model")
    p.add_argument("--models-dir", help="where to put it (default: the stack's models folder)")
    p.set_defaults(handler=run_fetch_model)


def _add_serve(subparsers: Any) -> None:
    from services.detector.service import add_serve_command

    add_serve_command(subparsers)


#: Subcommand registrations, in help order.
SUBCOMMANDS: list[Callable[[Any], None]] = [
    _add_detect,
    _add_benchmark,
    _add_fetch_model,
    _add_serve,
]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand in :data:`SUBCOMMANDS`."""
    parser = argparse.ArgumentParser(
        prog="python -m services.detector", description="YOLO object detector"
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for register in SUBCOMMANDS:
        register(subparsers)
    return parser


def exit_code(error: StackError) -> int:
    """The exit code documented above for ``error``."""
    if isinstance(error, ConfigError):
        return EXIT_USAGE
    if isinstance(error, ModelError):
        return EXIT_MODEL
    if isinstance(error, BackendUnavailable):
        return EXIT_BACKEND
    return EXIT_IMAGE_FAILED


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default ``sys.argv[1:]``), run the subcommand, return its exit code."""
    args = build_parser().parse_args(argv)
    handler: Callable[[argparse.Namespace], int] = args.handler
    try:
        return handler(args)
    except StackError as exc:
        _error(str(exc))
        return exit_code(exc)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
