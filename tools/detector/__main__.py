"""python -m tools.detector [detect] [PATH ...] [options]
python -m tools.detector benchmark|prepare|fetch-model|fast-profile|export [options]

YOLO object detector: detect (the default) on photos, folders, videos, cameras or streams;
benchmark its stages per backend; prepare every model file a stack config needs, ahead of
serving; fetch the default model; measure the fast profile; export a TensorRT engine. What
each command does is tools/detector/cli.py (its exit codes too); errors are one line on stderr.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from common.cli import Command, options_from, service_main
from common.errors import StackError
from common.images import SAMPLES
from common.lifecycle import EXIT_INTERRUPTED, exit_code, run_main
from runtimes import BACKEND_CHOICES
from services.detector.contract import DetectorSettings
from tools.detector import cli

PROG = "python -m tools.detector"
MODEL_HELP = "ONNX model (default: the YOLOv5s COCO model, fetched)"
#: The thresholds' defaults: those of the settings, stated once there.
_DEFAULTS = DetectorSettings()


def _detect_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "paths",
        nargs="*",
        metavar="PATH",
        help="image file, folder of images, video file, device:N, /dev/videoN, a stream URL "
        "(rtsp://, http://, ...) or a bundled photo sample:NAME "
        f"({', '.join(SAMPLES)}); default: {cli.DEFAULT_SAMPLE}",
    )
    p.add_argument("--model", help=MODEL_HELP)
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


def detect(args: argparse.Namespace) -> int:
    options = options_from(cli.DetectOptions, args, paths=tuple(args.paths), as_json=args.json)
    return cli.run_detect(options)


def _benchmark_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", help=MODEL_HELP)
    p.add_argument(
        "--backend",
        action="append",
        help="backend to time: onnx, tensorrt, cuda, openvino or auto; repeat to compare "
        "(default onnx)",
    )
    p.add_argument("--runs", type=int, default=50, help="timed runs (default 50)")
    p.add_argument("--warmup", type=int, default=5, help="untimed runs first (default 5)")
    p.add_argument("--image", help="image to time on (default: scikit-image chelsea)")
    p.add_argument(
        "--images",
        help="folder of photos for the agreement score (default: six scikit-image photos)",
    )
    p.add_argument("--conf", type=float, default=_DEFAULTS.conf, help="reference threshold")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--variants",
        help="compare backend:precision:size variants instead, e.g. "
        "onnx:fp32:640,onnx:int8:480,onnx:fp32:416 (tools/benchmarks/variants.py)",
    )


def benchmark(args: argparse.Namespace) -> int:
    from tools.benchmarks.detector import BenchmarkOptions

    backends = tuple(args.backend or ())
    return cli.run_benchmark(
        options_from(BenchmarkOptions, args, backends=backends, as_json=args.json)
    )


def _prepare_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="stack config (default deploy/stack.toml)")
    p.add_argument("--backend", help="override detector.backend (as the detector's serve)")
    p.add_argument("--model", help="override detector.model (as the detector's serve)")


def prepare(args: argparse.Namespace) -> int:
    overrides = {k: v for k, v in (("backend", args.backend), ("model", args.model)) if v}
    return cli.run_prepare(args.config, overrides)


def _fetch_model_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--models-dir", help="where to put it (default: the stack's models folder)")


def fetch_model(args: argparse.Namespace) -> int:
    return cli.run_fetch_model(args.models_dir)


def _fast_profile_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="stack config (default deploy/stack.toml)")


def fast_profile(args: argparse.Namespace) -> int:
    return cli.run_fast_profile(args.config)


def _export_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--backend", choices=["tensorrt"], default="tensorrt", help="engine kind")
    p.add_argument("--model", help=MODEL_HELP)
    p.add_argument("--precision", choices=["fp32", "fp16", "int8"], default="fp16")
    p.add_argument("--calib", help="folder of calibration images (needed to build int8)")
    p.add_argument("--batch", type=int, default=1, help="largest batch served (profile 1/N/N)")
    p.add_argument("--workspace-gb", type=float, default=4.0, help="builder scratch memory")
    p.add_argument("--cache-dir", help="engine cache folder (default: <models>/engines)")


def export(args: argparse.Namespace) -> int:
    return cli.run_export(options_from(cli.ExportOptions, args))


#: In help order.
COMMANDS = [
    Command("detect", "detect objects in images, folders, videos, a camera device or a bundled "
            "photo", _detect_arguments, detect),
    Command("benchmark", "time each stage on one or more backends", _benchmark_arguments,
            benchmark),
    Command("prepare", "prepare every model file a stack config needs (fetch, input size, INT8, "
            "the fast profile), ahead of serving", _prepare_arguments, prepare),
    Command("fetch-model", "fetch and convert the default model", _fetch_model_arguments,
            fetch_model),
    Command("fast-profile", "measure the CPU variants once and cache the fast profile's choice",
            _fast_profile_arguments, fast_profile),
    Command("export", "build and cache a TensorRT engine for a model", _export_arguments, export),
]  # fmt: skip


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default ``sys.argv[1:]``), run the command, return its exit code; a
    StackError is one line, ``error: ...``."""
    try:
        return service_main(PROG, __doc__ or "", COMMANDS, argv, default="detect")
    except StackError as exc:
        cli.print_error(str(exc))
        return exit_code(exc)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    run_main(main, "detector")
