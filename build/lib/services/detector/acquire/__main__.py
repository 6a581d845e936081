"""``python -m services.detector.acquire [--models-dir DIR]``: fetch and convert the default
model if needed, and print its path (``python -m services.detector fetch-model`` does the same)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from common.errors import StackError
from services.detector.model_files import MODELS_DIR_ENV, ensure_default_model


def main(argv: Sequence[str] | None = None) -> int:
    """Fetch and convert the default model into ``--models-dir``; print its path."""
    parser = argparse.ArgumentParser(
        prog="python -m services.detector.acquire",
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
