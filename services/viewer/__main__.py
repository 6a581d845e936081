"""python -m services.viewer [serve|layout] ...

serve (the default) runs the live view: a Foxglove WebSocket server on viewer.host:viewer.port
showing each camera with its detections, the laser scan, the simulator's world, the command, the
controller's state and the metrics (docs/viewer.md). layout writes the Foxglove layout that
arranges them (deploy/foxglove/layout.json by default), an image panel and a depth panel for
each camera of the config.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from common.cli import Command, add_config, service_main
from common.lifecycle import run_main, setup_logging, stop_event
from stack.config_file import load_config


def serve(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    setup_logging("viewer")
    from services.viewer import service

    return service.run(config, stop)


def _layout_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, help="where to write it (default the shipped file)")
    p.add_argument(
        "--no-depth", action="store_true", help="no depth panels (cameras without depth)"
    )
    add_config(p)


def layout(args: argparse.Namespace) -> int:
    from services.viewer import layout

    cameras = list(load_config(args.config).all_cameras)  # an image panel for each
    print(layout.write(args.out or layout.LAYOUT_FILE, cameras, depth=not args.no_depth))
    return 0


COMMANDS = [
    Command("serve", "run the live Foxglove view", add_config, serve),
    Command("layout", "write the Foxglove layout file", _layout_arguments, layout),
]
DESCRIPTION = (__doc__ or "").split("\n\n", 1)[-1]


def main(argv: Sequence[str] | None = None) -> int:
    return service_main("python -m services.viewer", DESCRIPTION, COMMANDS, argv)


if __name__ == "__main__":
    run_main(main, "viewer")
