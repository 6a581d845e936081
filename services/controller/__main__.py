"""python -m services.controller [--config FILE] [--mode track|follow]"""

from __future__ import annotations

import argparse
import dataclasses

from common.lifecycle import run_main, setup_logging, stop_event
from common.settings import load_config


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m services.controller", description=__doc__)
    parser.add_argument("--config", help="stack config (default deploy/stack.toml)")
    parser.add_argument("--mode", choices=["track", "follow"], help="override controller.mode")
    args = parser.parse_args()
    stop = stop_event()
    config = load_config(args.config)
    if args.mode:
        config = dataclasses.replace(
            config, controller=dataclasses.replace(config.controller, mode=args.mode)
        )
    setup_logging("controller")
    from services.controller.service import run

    return run(config, stop)


if __name__ == "__main__":
    run_main(main, "controller")
