"""python -m tools.report [report] [--duration S | --session FILE] [options]

report (the only command) runs the stack for a while (or reads a saved session) and writes
report.md with plots.
"""

from __future__ import annotations

import argparse

from common.cli import Command, service_main
from common.lifecycle import run_main, setup_logging, stop_event


def _report_arguments(p: argparse.ArgumentParser) -> None:
    from tools.report import report

    report.add_arguments(p)


def report(args: argparse.Namespace) -> int:
    stop = stop_event()
    from tools.report import report

    setup_logging("report", "WARNING")
    return report.run(args, stop)


COMMANDS = [Command("report", "write report.md and plots of a run", _report_arguments, report)]


def main() -> int:
    return service_main("python -m tools.report", __doc__ or "", COMMANDS, default="report")


if __name__ == "__main__":
    run_main(main, "report")
