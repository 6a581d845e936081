"""python -m services.controller [serve] [--config FILE] [--mode track|follow]
python -m services.controller estop engage|release [--reason TEXT] [--config FILE]

serve (the default) runs the controller; estop latches or releases the emergency stop.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

from common.cli import Command, add_config, service_main
from common.contracts import ControllerMode
from common.errors import StackError
from common.lifecycle import exit_code, run_main, setup_logging, stop_event
from common.priority import own_session


def _serve_arguments(p: argparse.ArgumentParser) -> None:
    add_config(p)
    p.add_argument("--mode", choices=[m.value for m in ControllerMode], help="override mode")


def serve(args: argparse.Namespace) -> int:
    from stack.config_file import load_config  # every service's settings: not the e-stop's

    stop = stop_event()
    config = load_config(args.config)
    if args.mode:
        controller = dataclasses.replace(config.controller, mode=ControllerMode(args.mode))
        config = dataclasses.replace(config, controller=controller)
    setup_logging("controller")
    from services.controller import service

    return service.run(config, stop)


def _estop_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("action", choices=["engage", "release"])
    p.add_argument("--reason", default="", help="why (logged by the controller)")
    add_config(p)


def estop(args: argparse.Namespace) -> int:
    """The operator's e-stop command: its errors are its own ("estop: error: ..."), not the
    controller service's. It reads only the config's [zenoh] and [stack] tables: a mistake
    elsewhere in the file does not hold up a stop. It runs in a session of its own (through
    ``zstack estop`` already), with a share of the CPU of its own."""
    code = own_session()
    if code is not None:
        return code
    handed = False  # whether the controller on this host took the engage (its socket)
    if args.action == "engage":
        from stack.local_estop import engage_here

        # zstack did this already, first of all; again is harmless (an engage is idempotent)
        # and tells this command whether the local road took it.
        handed = not engage_here(args.config, args.reason)
    try:
        from stack.config_read import load_bus_settings

        settings, stack = load_bus_settings(args.config)
        setup_logging("estop", "WARNING")
        from services.controller.estop_command import send_estop

        return send_estop(settings, stack.prefix, args.action == "engage", args.reason)
    except StackError as exc:
        note = (
            " (the controller on this host took the engage through its local e-stop socket,"
            " but no status of it confirmed the stop)"
            if handed
            else ""
        )
        print(f"estop: error: {exc}{note}", file=sys.stderr)
        return exit_code(exc)


COMMANDS = [
    Command("serve", "run the controller", _serve_arguments, serve),
    Command("estop", "latch (engage) or release the emergency stop", _estop_arguments, estop),
]


def main() -> int:
    return service_main("python -m services.controller", __doc__ or "", COMMANDS)


if __name__ == "__main__":
    run_main(main, "controller", skip_finalizing=True)
