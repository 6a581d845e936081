"""python -m tools.evaluation [evaluate] MODEL DATASET [options]

evaluate (the only command) scores a model on a labelled dataset, a COCO JSON file or a YOLO
folder (docs/evaluation.md).
"""

from __future__ import annotations

import argparse

from common.cli import Command, service_main
from common.lifecycle import run_main


def _evaluate_arguments(p: argparse.ArgumentParser) -> None:
    from tools.evaluation import evaluate

    evaluate.add_arguments(p)


def evaluate(args: argparse.Namespace) -> int:
    from tools.evaluation import evaluate

    return evaluate.run(args)  # Ctrl-C: KeyboardInterrupt, exit 130


COMMANDS = [Command("evaluate", "accuracy on a labelled dataset", _evaluate_arguments, evaluate)]


def main() -> int:
    return service_main("python -m tools.evaluation", __doc__ or "", COMMANDS, default="evaluate")


if __name__ == "__main__":
    run_main(main, "evaluate")
