"""python -m services.metrics [serve|query|evaluate|report] ...

serve (the default) runs the metrics service; query asks a running one and prints its JSON;
evaluate scores a model on a labelled dataset (see docs/evaluation.md); report runs the stack
for a while (or reads a saved session) and writes report.md with plots.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

from common.config_file import load_config
from common.errors import StackError
from common.lifecycle import run_main, setup_logging, stop_event

COMMANDS = ("serve", "query", "evaluate", "report")


def build_parser() -> argparse.ArgumentParser:
    from services.metrics import evaluate, report

    parser = argparse.ArgumentParser(
        prog="python -m services.metrics", description=(__doc__ or "").split("\n\n", 1)[-1]
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, text in (("serve", "run the metrics service"), ("query", "print its JSON")):
        p = sub.add_parser(name, help=text)
        p.add_argument("--config", help="stack config (default deploy/stack.toml)")
        if name == "query":
            p.add_argument("--timeout", type=float, default=5.0, help="seconds to wait")
    evaluate.add_arguments(sub.add_parser("evaluate", help="accuracy on a labelled dataset"))
    report.add_arguments(sub.add_parser("report", help="write report.md and plots of a run"))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or (argv[0] not in COMMANDS and argv[0] not in ("-h", "--help")):
        argv.insert(0, "serve")  # `python -m services.metrics --config X` still serves
    args = build_parser().parse_args(argv)
    if args.command == "evaluate":
        from services.metrics import evaluate

        return evaluate.run(args)  # Ctrl-C: KeyboardInterrupt, exit 130
    stop = stop_event()
    if args.command == "report":
        from services.metrics import report

        setup_logging("report", "WARNING")
        return report.run(args, stop)
    config = load_config(args.config)
    setup_logging("metrics", "WARNING" if args.command == "query" else None)
    from services.metrics import service

    if args.command == "query":
        answer = service.query(config, args.timeout)
        if answer is None:
            raise StackError(f"no metrics service answered within {args.timeout:.0f} s")
        print(json.dumps(answer, indent=2))
        return 0
    return service.run(config, stop)


if __name__ == "__main__":
    run_main(main, "metrics")
