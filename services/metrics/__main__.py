"""python -m services.metrics [serve|query|pool] ...

serve (the default) runs the metrics service; query asks a running one and prints its JSON
(on stdout), after the cameras announced and every warning as a WARNING line (on stderr);
pool prints the whole detector pool from its tokens, from any host (a GPU box included).
Accuracy on a labelled dataset is ``python -m tools.evaluation``; a report of a run,
``python -m tools.report``.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

from common.cli import Command, add_config, service_main
from common.cli import build_parser as _build
from common.lifecycle import run_main, setup_logging, stop_event
from services.metrics.summary import summary
from stack.config_file import load_config


def serve(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    setup_logging("metrics")
    from services.metrics import service

    return service.run(config, stop)


def _query_arguments(p: argparse.ArgumentParser) -> None:
    add_config(p)
    p.add_argument("--timeout", type=float, default=5.0, help="seconds to wait")


def query(args: argparse.Namespace) -> int:
    config = load_config(args.config)
    setup_logging("metrics", "WARNING")
    from services.metrics import service

    answer = service.query(config, args.timeout)
    for line in summary(answer, config.stack.prefix):  # for a person; the JSON for programs
        print(line, file=sys.stderr)
    print(json.dumps(answer, indent=2))
    return 0


def pool(args: argparse.Namespace) -> int:
    """The whole pool from its tokens (services/metrics/pool_view.py), as JSON on stdout."""
    config = load_config(args.config)
    setup_logging("metrics", "WARNING")
    from services.metrics import service

    view = service.pool(config)
    for name in view["unserved"]:
        print(
            f"WARNING pool: camera {name} is announced and no live worker serves it",
            file=sys.stderr,
        )
    print(json.dumps(view, indent=2))
    return 0


COMMANDS = [
    Command("serve", "run the metrics service", add_config, serve),
    Command("query", "ask a running metrics service and print its JSON", _query_arguments, query),
    Command(
        "pool", "print the detector pool's workers and cameras (from any host)", add_config, pool
    ),
]
DESCRIPTION = (__doc__ or "").split("\n\n", 1)[-1]


def build_parser() -> argparse.ArgumentParser:
    return _build("python -m services.metrics", DESCRIPTION, COMMANDS)


def main(argv: Sequence[str] | None = None) -> int:
    return service_main("python -m services.metrics", DESCRIPTION, COMMANDS, argv)


if __name__ == "__main__":
    run_main(main, "metrics")
