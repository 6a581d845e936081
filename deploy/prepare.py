"""python -m deploy.prepare [--config FILE]

What `make run` does before it starts the stack: fetch and convert the default model, but only
when the config runs a detector on it (``detector.model`` empty). A config that names its own
model, or runs no detector, needs nothing fetched.
"""

from __future__ import annotations

import argparse
import sys

from common.config_file import load_config
from common.lifecycle import run_main


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m deploy.prepare", description=__doc__)
    parser.add_argument("--config", help="stack config (default deploy/stack.toml)")
    args = parser.parse_args()
    config = load_config(args.config)
    if "detector" not in config.supervisor.services:
        print("prepare: no detector in supervisor.services: no model to fetch", file=sys.stderr)
        return 0
    if config.detector.model:
        print(
            f"prepare: detector.model is {config.detector.model}: nothing to fetch", file=sys.stderr
        )
        return 0
    from services.detector.model_store import ensure_default_model

    def progress(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    print(ensure_default_model(progress=progress))
    return 0


if __name__ == "__main__":
    run_main(main, "prepare")
