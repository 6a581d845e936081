"""python -m tests.integration.pool_view --config FILE [--seconds S]

What the detector pool of a running stack looks like from one host, for a test in another
network namespace (tests/integration/test_readme_pool.py): it joins as "observer", listens for
``--seconds`` and prints one JSON object: the workers' announcements (capacity, prefixes); its
robot's cameras' (rate); the serving tokens, worker -> cameras, at the start and at the end of
the window (under ``detector.pool_prefix``: another robot's cameras by their pool names,
``<prefix>/<camera>``); the distinct publishers of each camera's detections in the window; and
what the controller's statuses said in it: each set of stale cameras and its target's cameras.
Exit 1 with one line if the router cannot be reached.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections import defaultdict
from typing import Any

from common.announce import from_chunk
from common.bus import Sample
from common.errors import ConfigError, DecodeError
from common.keys import Keys
from common.messages import CameraAnnouncement, ControllerStatus, WorkerAnnouncement
from common.zenoh_bus import ZenohBus, open_session
from stack.config_file import load_config

TOKENS_TIMEOUT_S = 2.0


def _serving(bus: ZenohBus, keys: Keys) -> dict[str, list[str]]:
    out: dict[str, set[str]] = defaultdict(set)
    for key in bus.live_tokens(keys.all_pool_serving(), TOKENS_TIMEOUT_S):
        parts = keys.pool_serving_parts(key)
        if parts is not None:
            out[parts[0]].add(parts[2])
    return {w: sorted(c) for w, c in sorted(out.items())}


def _workers(bus: ZenohBus, keys: Keys) -> dict[str, dict[str, Any]]:
    out = {}
    for key in bus.live_tokens(keys.all_worker_announcements(), TOKENS_TIMEOUT_S):
        parts = keys.worker_announcement_parts(key)
        if parts is None:
            continue
        try:
            a = from_chunk(WorkerAnnouncement.decode, parts[1])
        except DecodeError:
            continue
        out[a.worker] = {"capacity_hz": a.capacity_hz, "prefixes": list(a.prefixes)}
    return out


def _cameras(bus: ZenohBus, keys: Keys) -> dict[str, float]:
    out = {}
    for key in bus.live_tokens(keys.all_camera_announcements(), TOKENS_TIMEOUT_S):
        parts = keys.camera_announcement_parts(key)
        if parts is None:
            continue
        try:
            out[parts[0]] = from_chunk(CameraAnnouncement.decode, parts[1]).rate_hz
        except DecodeError:
            continue
    return out


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.integration.pool_view")
    parser.add_argument("--config", required=True)
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    config = load_config(args.config, environ={})
    keys = Keys(config.stack.prefix)
    pool = Keys(config.detector.pool_prefix or config.stack.prefix)  # the pool's own tokens
    try:
        bus = ZenohBus(open_session(config.zenoh, config.principal("observer")))
    except ConfigError as exc:
        print(f"pool_view: {exc}", file=sys.stderr)
        return 1
    lock = threading.Lock()
    sources: dict[str, set[str]] = defaultdict(set)
    stale_sets: set[tuple[str, ...]] = set()
    targets: set[str] = set()

    def on_detections(sample: Sample) -> None:
        camera = sample.key.split("/")[-2]  # <prefix>/detector/<camera>/detections
        with lock:
            sources[camera].add(sample.source)

    def on_status(sample: Sample) -> None:
        try:
            s = ControllerStatus.decode(sample.payload)
        except DecodeError:
            return
        with lock:
            stale_sets.add(tuple(sorted(s.stale_cameras)))
            if s.camera:
                targets.add(s.camera)

    subs = [
        bus.subscribe(keys.all_detections(), on_detections),
        bus.subscribe(keys.controller_status(), on_status),
    ]
    before = _serving(bus, pool)
    time.sleep(args.seconds)  # the listening window itself, not a wait for a condition
    view = {
        "workers": _workers(bus, pool),
        "cameras": _cameras(bus, keys),
        "serving_before": before,
        "serving": _serving(bus, pool),
    }
    for sub in subs:
        sub.undeclare()
    with lock:
        view["publishers"] = {c: len(s) for c, s in sorted(sources.items())}
        view["controller"] = {
            "statuses": bool(stale_sets),
            "stale_sets": sorted(list(s) for s in stale_sets),
            "target_cameras": sorted(targets),
        }
    bus.close()
    print(json.dumps(view))
    return 0


if __name__ == "__main__":
    sys.exit(main())
