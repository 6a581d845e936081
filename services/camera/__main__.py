"""python -m services.camera [serve] [--config FILE] [--camera NAME] [--source SPEC] [--rate HZ]

serve (the default) reads one camera's source and publishes its frames: camera NAME of the
config (default: the first, stack.camera). Each camera of a stack is a process of its own,
named as the supervisor names it: ``camera`` for the first, ``camera_<name>`` for the others.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

from common.cli import Command, add_config, service_main
from common.errors import StackError
from common.lifecycle import exit_code, run_main, setup_logging, stop_event
from stack.config_file import load_config


def _serve_arguments(p: argparse.ArgumentParser) -> None:
    add_config(p)
    p.add_argument("--camera", help="the camera to serve, by name (default: stack.camera)")
    p.add_argument("--source", help="override that camera's source")
    p.add_argument("--rate", type=float, help="override that camera's rate_hz")


def serve(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    name = args.camera or config.stack.camera
    service = config.camera_services.get(name, "camera")
    try:
        camera = config.camera_settings(name)
        if args.source:
            camera = dataclasses.replace(camera, source=args.source)
        if args.rate:
            camera = dataclasses.replace(camera, rate_hz=args.rate)
        setup_logging(service)
        from services.camera.service import run

        return run(config, name, camera, stop)
    except StackError as exc:
        # One line under this camera's own service name, so that the supervisor, which
        # watches ``camera_<name>``, reports it as that camera's error (run_main would say
        # ``camera`` for every one of them).
        print(f"{service}: error: {exc}", file=sys.stderr)
        return exit_code(exc)


COMMANDS = [
    Command("serve", "publish one camera's frames from its source", _serve_arguments, serve)
]


def main() -> int:
    return service_main("python -m services.camera", __doc__ or "", COMMANDS)


if __name__ == "__main__":
    run_main(main, "camera", skip_finalizing=True)
