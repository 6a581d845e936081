"""python -m services.metrics [serve|query] [--config FILE]

serve (the default) runs the metrics service; query asks a running one and prints its JSON.
"""

from __future__ import annotations

import argparse
import json

from common.errors import StackError
from common.lifecycle import run_main, setup_logging, stop_event
from common.settings import load_config


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m services.metrics", description=__doc__)
    parser.add_argument("command", nargs="?", default="serve", choices=["serve", "query"])
    parser.add_argument("--config", help="stack config (default deploy/stack.toml)")
    parser.add_argument("--timeout", type=float, default=5.0, help="query: seconds to wait")
    args = parser.parse_args()
    stop = stop_event()
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
