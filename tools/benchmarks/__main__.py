"""python -m tools.benchmarks recorder|ros2 [options]

recorder runs the default stack with and without the recorder, side by side; ros2 measures
what the ROS 2 bridge adds against the direct path. (The detector's own benchmark is
``python -m tools.detector benchmark``.)
"""

from __future__ import annotations

import argparse
import logging

from common.cli import Command, service_main
from common.lifecycle import run_main, setup_logging, stop_event


def _recorder_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="the stack to run (default deploy/stack.toml)")
    p.add_argument("--rounds", type=int, default=3, help="phases of each condition (default 3)")
    p.add_argument("--phase", type=float, default=20.0, help="seconds per phase (default 20)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def recorder(args: argparse.Namespace) -> int:
    stop = stop_event()
    logging.getLogger().setLevel(logging.WARNING)
    from tools.benchmarks import recorder as bench

    return bench.main(args.config, args.rounds, args.phase, args.json, stop)


def _ros2_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--runs", type=int, default=200, help="messages per path (default 200)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def ros2(args: argparse.Namespace) -> int:
    setup_logging("ros2-bench", "WARNING")
    from tools.benchmarks import ros2 as bench

    return bench.main(args.runs, args.json)


COMMANDS = [
    Command("recorder", "the stack's FPS and latency with and without the recorder",
            _recorder_arguments, recorder),
    Command("ros2", "the ROS 2 bridge's added latency against the direct path",
            _ros2_arguments, ros2),
]  # fmt: skip


def main() -> int:
    return service_main("python -m tools.benchmarks", __doc__ or "", COMMANDS, default=None)


if __name__ == "__main__":
    run_main(main, "benchmark")
