"""python -m services.sim [serve] [--config FILE]

serve (the default) runs the simulator as the stack's camera, laser and base. The scripted
scenarios and the soak that run the whole stack against it are ``python -m tools.scenarios``.
"""

from __future__ import annotations

import argparse

from common.cli import Command, add_config, service_main
from common.lifecycle import run_main, setup_logging, stop_event
from stack.config_file import load_config


def serve(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    setup_logging("sim")
    from services.sim.service import run

    return run(config, stop)


COMMANDS = [
    Command("serve", "run the simulated robot (camera, laser and base)", add_config, serve),
]  # fmt: skip


def main() -> int:
    return service_main("python -m services.sim", __doc__ or "", COMMANDS)


if __name__ == "__main__":
    run_main(main, "sim")
