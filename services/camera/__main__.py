"""python -m services.camera [--config FILE] [--source SPEC] [--rate HZ]"""

from __future__ import annotations

import argparse
import dataclasses

from common.config_file import load_config
from common.lifecycle import run_main, setup_logging, stop_event


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m services.camera", description=__doc__)
    parser.add_argument("--config", help="stack config (default deploy/stack.toml)")
    parser.add_argument("--source", help="override camera.source")
    parser.add_argument("--rate", type=float, help="override camera.rate_hz")
    args = parser.parse_args()
    stop = stop_event()
    config = load_config(args.config)
    camera = config.camera
    if args.source:
        camera = dataclasses.replace(camera, source=args.source)
    if args.rate:
        camera = dataclasses.replace(camera, rate_hz=args.rate)
    config = dataclasses.replace(config, camera=camera)
    setup_logging("camera")
    from services.camera.service import run

    return run(config, stop)


if __name__ == "__main__":
    run_main(main, "camera")
