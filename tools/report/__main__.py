"""python -m tools.report [report] [--duration S | --from FILE] [options]

report (the only command) runs the stack for a while (or reads a saved session) and writes
report.md with plots.
"""

from __future__ import annotations

import argparse

from common.cli import Command, options_from, service_main
from common.lifecycle import run_main, setup_logging, stop_event


def _report_arguments(p: argparse.ArgumentParser) -> None:
    from tools.report.report import DEFAULT_DURATION_S, DEFAULT_STARTUP_TIMEOUT_S

    p.add_argument("--out", required=True, help="folder for report.md, plots, session.json")
    p.add_argument("--config", help="stack config to run (default deploy/stack.toml)")
    p.add_argument(
        "--duration", type=float, help=f"seconds to record (default {DEFAULT_DURATION_S:.0f})"
    )
    p.add_argument("--from", dest="from_file", metavar="FILE", help="a saved session.json")
    p.add_argument(
        "--benchmark",
        action="append",
        metavar="FILE",
        help="detector `benchmark --json` output; repeat to compare backends",
    )
    p.add_argument(
        "--startup-timeout",
        type=float,
        default=DEFAULT_STARTUP_TIMEOUT_S,
        help=f"seconds to wait for the stack to be ready (default {DEFAULT_STARTUP_TIMEOUT_S:.0f})",
    )


def report(args: argparse.Namespace) -> int:
    stop = stop_event()
    from tools.report.report import ReportOptions, run

    setup_logging("report", "WARNING")
    options = options_from(
        ReportOptions,
        args,
        duration_s=args.duration,
        benchmarks=tuple(args.benchmark or ()),
        startup_timeout_s=args.startup_timeout,
    )
    return run(options, stop)


COMMANDS = [Command("report", "write report.md and plots of a run", _report_arguments, report)]


def main() -> int:
    return service_main("python -m tools.report", __doc__ or "", COMMANDS, default="report")


if __name__ == "__main__":
    run_main(main, "report")
