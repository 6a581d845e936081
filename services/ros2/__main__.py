"""python -m services.ros2 [serve] [--config FILE]

serve (the default) bridges the stack and a ROS 2 robot's graph over rmw_zenoh (docs/ros2.md).
"""

from __future__ import annotations

import argparse

from common.cli import Command, add_config, service_main
from common.lifecycle import run_main, setup_logging, stop_event
from stack.config_file import load_config


def serve(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    setup_logging("ros2")
    from services.ros2.service import run

    return run(config, stop)


COMMANDS = [
    Command("serve", "bridge the stack and a ROS 2 graph", add_config, serve),
]  # fmt: skip


def main() -> int:
    return service_main("python -m services.ros2", __doc__ or "", COMMANDS)


if __name__ == "__main__":
    run_main(main, "ros2")
