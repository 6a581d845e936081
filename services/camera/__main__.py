"""python -m services.camera [serve] [--config FILE] [--camera NAME] [--source SPEC] [--rate HZ]

serve (the default) reads the configured source of camera NAME (default: the first camera,
``stack.camera``) and publishes its frames, as that camera's service (``camera`` or
``camera_<name>``).
"""

from __future__ import annotations

import argparse
import dataclasses

from common.cli import Command, add_config, service_main
from common.config_file import load_config
from common.lifecycle import run_main, setup_logging, stop_event


def _serve_arguments(p: argparse.ArgumentParser) -> None:
    add_config(p)
    p.add_argument("--camera", help="which camera of the config (default: stack.camera)")
    p.add_argument("--source", help="override the camera's source")
    p.add_argument("--rate", type=float, help="override the camera's rate_hz")


def serve(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    name = args.camera or config.stack.camera
    camera = config.camera_settings(name)
    if args.source:
        camera = dataclasses.replace(camera, source=args.source)
    if args.rate:
        camera = dataclasses.replace(camera, rate_hz=args.rate)
    setup_logging(config.camera_services[name])
    from services.camera.service import run

    return run(config, stop, name, camera)


COMMANDS = [Command("serve", "publish frames from the configured source", _serve_arguments, serve)]


def main() -> int:
    return service_main("python -m services.camera", __doc__ or "", COMMANDS)


if __name__ == "__main__":
    run_main(main, "camera")
