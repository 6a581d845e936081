"""python -m tests.integration.rogue --config FILE --as PRINCIPAL [--endpoint EP] [--no-cert]

A principal (a role of FILE's stack, named as its: ``Config.principal``) misusing its
credentials inside a network namespace (tests/integration/
test_two_hosts.py): it joins the stack of FILE as PRINCIPAL (on ``--endpoint`` instead of the
config's, e.g. another host's router) and, until SIGINT or SIGTERM, puts every 0.1 s what no
worker may put (garbage on cmd_vel, the e-stop, the controller's counters and every camera's
frames) and what a worker may (empty detections of each camera, its header's source
``rogue-<PRINCIPAL>``, so a reader can tell them apart). It prints ``{"kind": "open"}`` once
its session is up. ``--no-cert``: it only tries to join over TLS with no certificate of its
own, and prints ``{"kind": "refused", "error": ...}`` or ``{"kind": "open"}``, then exits.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time

from common.clock import now
from common.errors import ConfigError
from common.keys import Keys
from common.lifecycle import stop_event
from common.messages import Header
from common.zenoh_bus import open_session
from stack.config_file import load_config
from tests.integration.test_safety import person

PERIOD_S = 0.1
OPEN_TIMEOUT_S = 60.0  # the router may start after it


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m tests.integration.rogue")
    parser.add_argument("--config", required=True)
    parser.add_argument("--as", dest="principal", required=True)
    parser.add_argument("--endpoint", default="")
    parser.add_argument("--no-cert", action="store_true")
    args = parser.parse_args()
    stop = stop_event()
    config = load_config(args.config, environ={})
    settings = dataclasses.replace(
        config.zenoh, endpoint=args.endpoint or config.zenoh.endpoint, connect=()
    )
    if args.no_cert:
        settings = dataclasses.replace(settings, auth="none")  # TLS still, no certificate
        try:
            open_session(settings, config.principal(args.principal)).close()
        except ConfigError as exc:
            print(json.dumps({"kind": "refused", "error": str(exc)}), flush=True)
            sys.exit(0)
        print(json.dumps({"kind": "open"}), flush=True)
        sys.exit(0)
    deadline = time.monotonic() + OPEN_TIMEOUT_S
    while True:
        try:
            session = open_session(settings, config.principal(args.principal))
            break
        except ConfigError:
            if time.monotonic() > deadline or stop.wait(0.5):
                raise
    keys = Keys(config.stack.prefix)
    cameras = list(config.all_cameras)
    forbidden = [keys.cmd_vel(), keys.estop(), keys.counters("controller")]
    forbidden += [keys.frame(c) for c in cameras]
    print(json.dumps({"kind": "open"}), flush=True)
    seq = 0
    while not stop.wait(PERIOD_S):
        seq += 1
        for key in forbidden:
            session.put(key, b"rogue")
        for camera in cameras:
            at = now()
            header = Header(
                stamp_ns=at.wall_ns, frame_id=camera, seq=seq, source=f"rogue-{args.principal}"
            )
            session.put(keys.detections(camera), person(header, 0).encode())
    session.close()
    sys.exit(0)


if __name__ == "__main__":
    main()
