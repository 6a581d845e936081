"""python -m services.camera [serve] [--config FILE] [--source SPEC] [--rate HZ]

serve (the default) reads the configured source and publishes its frames.
"""

from __future__ import annotations

import argparse
import dataclasses

from common.cli import Command, add_config, service_main
from common.config_file import load_config
from common.lifecycle import run_main, setup_logging, stop_event


def _serve_arguments(p: argparse.ArgumentParser) -> None:
    add_config(p)
    p.add_argument("--source", help="override camera.source")
    p.add_argument("--rate", type=float, help="override camera.rate_hz")


def serve(args: argparse.Namespace) -> int:
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


COMMANDS = [Command("serve", "publish frames from the configured source", _serve_arguments, serve)]


def main() -> int:
    return service_main("python -m services.camera", __doc__ or "", COMMANDS)


if __name__ == "__main__":
    run_main(main, "camera")
