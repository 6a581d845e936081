"""python -m tests.integration.probe --config FILE

A test's eyes inside a network namespace (tests/integration/test_two_hosts.py): it joins the
stack as "observer" and prints one JSON line per detections (of any camera), cmd_vel and
controller status sample (a detections line names its header's source), per detector
worker's counters (the cameras it serves, the members of the pool it counts, the garbage frames
it dropped) and per health token that comes or goes, stamped with the system's
monotonic clock (shared by every namespace of the host), so that a test in another namespace
can read what the stack does there. It prints
``{"kind": "open"}`` once its session is up, and runs until SIGINT or SIGTERM.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from common.errors import ConfigError, DecodeError
from common.keys import Keys
from common.lifecycle import stop_event
from common.messages import ControllerStatus, Detections, ServiceCounters, Twist
from common.settings import is_detector_service
from common.zenoh_bus import open_session
from stack.config import Config
from stack.config_file import load_config

_lock = threading.Lock()
OPEN_TIMEOUT_S = 60.0  # a router (client mode) may start after the probe


def emit(kind: str, **fields: Any) -> None:
    line = json.dumps({"kind": kind, "t": time.monotonic(), **fields})
    with _lock:
        print(line, flush=True)


def _on(kind: str, summary: Callable[[bytes], dict[str, Any]]) -> Callable[[zenoh.Sample], None]:
    def handle(sample: zenoh.Sample) -> None:
        try:
            emit(kind, **summary(sample.payload.to_bytes()))
        except DecodeError as exc:
            emit("garbage", key=str(sample.key_expr), error=str(exc))

    return handle


def _on_health(sample: zenoh.Sample) -> None:
    service = str(sample.key_expr).rsplit("/", 1)[-1]
    emit("health", service=service, present=sample.kind == zenoh.SampleKind.PUT)


def _on_detections(sample: zenoh.Sample) -> None:
    camera = str(sample.key_expr).split("/")[-2]  # <prefix>/detector/<camera>/detections
    try:
        d = Detections.decode(sample.payload.to_bytes())
    except DecodeError as exc:
        emit("garbage", key=str(sample.key_expr), error=str(exc))
        return
    age_ms = (time.time_ns() - d.header.stamp_ns) / 1e6
    emit(
        "detections", camera=camera, classes=list(d.class_names), age_ms=age_ms,
        source=d.header.source,
    )  # fmt: skip


def _worker(raw: bytes) -> dict[str, Any]:
    c = ServiceCounters.decode(raw)
    serving = sorted(
        n.split(".", 1)[1] for n, v in c.counters.items() if n.startswith("serving.") and v > 0
    )
    return {
        "service": c.service, "serving": serving, "members": c.counters.get("pool_members", 0),
        "bad_frames": c.counters.get("bad_input.frame", 0),
    }  # fmt: skip


def _twist(raw: bytes) -> dict[str, Any]:
    t = Twist.decode(raw)
    return {"zero": t.is_zero, "v": t.linear[0], "w": t.angular[2]}


def _status(raw: bytes) -> dict[str, Any]:
    s = ControllerStatus.decode(raw)
    return {"state": str(s.state), "reason": s.reason, "seq": s.header.seq}


def _open(config: Config, stop: threading.Event) -> zenoh.Session:
    """The probe's session; in client mode the router may not listen yet: retry for a while."""
    deadline = time.monotonic() + OPEN_TIMEOUT_S
    while True:
        try:
            return open_session(config.zenoh, config.principal("observer"))
        except ConfigError:
            if time.monotonic() > deadline or stop.wait(0.5):
                raise


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m tests.integration.probe")
    parser.add_argument("--config", required=True)
    args = parser.parse_args()
    stop = stop_event()
    config = load_config(args.config, environ={})
    keys = Keys(config.stack.prefix)
    session = _open(config, stop)
    on_counters = _on("worker", _worker)

    def on_worker(sample: zenoh.Sample) -> None:
        if is_detector_service(str(sample.key_expr).rsplit("/", 1)[-1]):
            on_counters(sample)

    subs = [
        session.declare_subscriber(keys.all_detections(), _on_detections),
        session.declare_subscriber(keys.all_counters(), on_worker),
        session.declare_subscriber(keys.cmd_vel(), _on("cmd_vel", _twist)),
        session.declare_subscriber(keys.controller_status(), _on("status", _status)),
        session.liveliness().declare_subscriber(keys.all_health(), _on_health, history=True),
    ]
    emit("open")
    stop.wait()
    for sub in subs:
        sub.undeclare()
    session.close()
    sys.exit(0)


if __name__ == "__main__":
    main()
