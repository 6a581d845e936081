"""python -m tools.evaluation [evaluate] --dataset FILE|FOLDER [--model FILE] [options]

evaluate (the only command) scores a model on a labelled dataset, a COCO JSON file or a YOLO
folder (docs/evaluation.md).
"""

from __future__ import annotations

import argparse

from common.cli import Command, options_from, service_main
from common.lifecycle import run_main


def _evaluate_arguments(p: argparse.ArgumentParser) -> None:
    from services.detector.contract import DetectorSettings
    from tools.evaluation.accuracy import DEFAULT_CONF_THRESHOLD
    from tools.evaluation.evaluate import DEFAULT_EVAL_CONF

    default_iou = DetectorSettings().iou
    p.add_argument("--dataset", required=True, help="COCO JSON file or YOLO folder")
    p.add_argument("--images", help="COCO: folder the file_names are relative to")
    p.add_argument("--model", help="ONNX model (default: the YOLOv5s COCO model)")
    p.add_argument("--backend", default="onnx", help="detector backend (default onnx)")
    p.add_argument(
        "--conf",
        type=float,
        default=DEFAULT_EVAL_CONF,
        help=f"score floor of the detections fed to mAP (default {DEFAULT_EVAL_CONF})",
    )
    p.add_argument(
        "--iou", type=float, default=default_iou, help=f"NMS IoU (default {default_iou})"
    )
    p.add_argument(
        "--conf-threshold",
        type=float,
        default=DEFAULT_CONF_THRESHOLD,
        help=f"score at which precision and recall are read (default {DEFAULT_CONF_THRESHOLD})",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")


def evaluate(args: argparse.Namespace) -> int:
    from tools.evaluation.evaluate import EvaluateOptions, run

    options = options_from(EvaluateOptions, args, as_json=args.json)
    return run(options)  # Ctrl-C: KeyboardInterrupt, exit 130


COMMANDS = [Command("evaluate", "accuracy on a labelled dataset", _evaluate_arguments, evaluate)]


def main() -> int:
    return service_main("python -m tools.evaluation", __doc__ or "", COMMANDS, default="evaluate")


if __name__ == "__main__":
    run_main(main, "evaluate")
