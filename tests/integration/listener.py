"""python -m tests.integration.listener --config FILE --principal NAME KEY_EXPR...

A listener that a test can freeze (SIGSTOP): it joins the stack as ``NAME``, subscribes to
each ``KEY_EXPR`` (counting what it receives, nothing more), prints ``subscribed`` once its
subscribers are declared, and runs until SIGINT or SIGTERM. Frozen, it reads nothing from its
link, as a hung or hostile client would (tests/integration/test_safety_listeners.py).
"""

from __future__ import annotations

import argparse

from common.lifecycle import stop_event
from common.zenoh_bus import open_session
from stack.config_file import load_config


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m tests.integration.listener")
    parser.add_argument("--config", required=True)
    parser.add_argument("--principal", required=True)
    parser.add_argument("key_exprs", nargs="+")
    args = parser.parse_args()
    stop = stop_event()
    config = load_config(args.config, environ={})
    received = [0]
    with open_session(config.zenoh, config.principal(args.principal)) as session:
        for key_expr in args.key_exprs:
            session.declare_subscriber(
                key_expr, lambda _s: received.__setitem__(0, received[0] + 1)
            )
        print("subscribed", flush=True)
        stop.wait()
    print(f"received {received[0]}", flush=True)


if __name__ == "__main__":
    main()
