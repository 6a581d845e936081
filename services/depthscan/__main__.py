"""python -m services.depthscan [serve] [--config FILE]

serve (the default) runs the depth scan stage: each announced depth camera's virtual scan and
the depth cameras' memory, for the controller (docs/depth.md).
"""

from __future__ import annotations

import argparse

from common.cli import Command, add_config, service_main
from common.lifecycle import run_main, setup_logging, stop_event


def serve(args: argparse.Namespace) -> int:
    from stack.config_file import load_config

    stop = stop_event()
    config = load_config(args.config)
    setup_logging("depthscan")
    from services.depthscan import service

    return service.run(config, stop)


COMMANDS = [Command("serve", "run the depth scan stage", add_config, serve)]


def main() -> int:
    return service_main("python -m services.depthscan", __doc__ or "", COMMANDS)


if __name__ == "__main__":
    run_main(main, "depthscan")
