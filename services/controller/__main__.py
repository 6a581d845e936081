"""python -m services.controller [serve] [--config FILE] [--mode track|follow]
python -m services.controller estop engage|release [--reason TEXT] [--config FILE]

serve (the default) runs the controller; estop latches or releases the emergency stop.
"""

from __future__ import annotations

import argparse
import dataclasses

from common.config_file import load_config
from common.lifecycle import run_main, setup_logging, stop_event


def main() -> int:
    parser = argparse.ArgumentParser(
        prog="python -m services.controller",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("command", nargs="?", default="serve", choices=["serve", "estop"])
    parser.add_argument("action", nargs="?", choices=["engage", "release"], help="for estop")
    parser.add_argument("--config", help="stack config (default deploy/stack.toml)")
    parser.add_argument("--mode", choices=["track", "follow"], help="override controller.mode")
    parser.add_argument("--reason", default="", help="estop: why (logged by the controller)")
    args = parser.parse_args()
    if args.command == "estop" and args.action is None:
        parser.error("estop needs 'engage' or 'release'")
    stop = stop_event()
    config = load_config(args.config)
    if args.mode:
        config = dataclasses.replace(
            config, controller=dataclasses.replace(config.controller, mode=args.mode)
        )
    setup_logging("controller")
    from services.controller import service

    if args.command == "estop":
        return service.send_estop(config, args.action == "engage", args.reason)
    return service.run(config, stop)


if __name__ == "__main__":
    run_main(main, "controller")
