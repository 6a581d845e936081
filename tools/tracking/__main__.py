"""python -m tools.tracking [SCENARIO ...] [--runs N] [--config FILE] [--mode follow|track]

The tracking evaluation (tools/tracking/bench.py): each scenario (default: the crowds'
``passing``, ``swap``, ``pillar``, ``fast_turn``, ``crowd``, ``handover``) run on the real
stack with each tracker, every run's detections replayed through every tracker, and one table
of HOTA, IDF1, MOTA and identity switches (TrackEval) beside the controller's lock: the share
of the time it was on the followed person while they showed, its switches to someone else and
the time to take them back after they reappeared. Progress goes to stderr; Ctrl-C stops at once.
"""

from __future__ import annotations

import argparse
import signal
import sys

from common.cli import add_config
from common.contracts import ControllerMode
from common.lifecycle import run_main, setup_logging
from simworld.scenarios import SCENARIOS
from stack.config_file import load_config
from tools.ports import add_port, use_ports

DEFAULT_SCENARIOS = ("passing", "swap", "pillar", "fast_turn", "crowd", "handover")


def _interrupt(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


def main() -> int:
    p = argparse.ArgumentParser(prog="python -m tools.tracking", description=__doc__)
    p.add_argument("scenarios", nargs="*", default=list(DEFAULT_SCENARIOS))
    p.add_argument("--runs", type=int, default=1, help="live runs per tracker (default 1)")
    p.add_argument(
        "--mode", choices=[m.value for m in ControllerMode], default=ControllerMode.FOLLOW.value
    )
    add_config(p)
    add_port(p)
    args = p.parse_args()
    unknown = [s for s in args.scenarios if s not in SCENARIOS or s == "demo"]
    if unknown:
        print(f"unknown scenario(s) {', '.join(unknown)}; see python -m tools.scenarios list",
              file=sys.stderr)  # fmt: skip
        return 2
    if args.runs < 1:
        print("--runs must be at least 1", file=sys.stderr)
        return 2
    signal.signal(signal.SIGTERM, _interrupt)
    config = load_config(args.config)
    setup_logging("tracking", "WARNING")
    use_ports(args.port)
    from tools.tracking.bench import run_table, table_text

    table = run_table(
        config, args.scenarios, args.runs, lambda m: print(m, file=sys.stderr),
        ControllerMode(args.mode),
    )  # fmt: skip
    print(table_text(table))
    return 0


if __name__ == "__main__":
    run_main(main, "tracking")
