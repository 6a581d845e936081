"""``zstack pool --config FILE``: the whole detector pool as one host sees it, from its tokens
alone (no metrics service needed: a GPU box runs none). Each worker's announcement (capacity,
robots) and the cameras it serves; each robot's announced cameras (rate) and who serves each,
those nobody serves listed. The pool is ``detector.pool_prefix`` (empty: ``stack.prefix``);
its robots are those the workers announce and the config's ``detector.prefixes``. The
announcements are read as every reader reads them (common/announce.py's one-shot form): one
that does not decode is logged (a WARNING line) and listed under ``bad_announcements``, never
shown as a worker or a camera."""

from __future__ import annotations

import logging
from collections import defaultdict
from typing import Any

from common.announce import cameras_now, workers_now
from common.bus import Bus
from common.keys import Keys
from common.pool_rule import pool_name
from stack.config import Config

TOKENS_TIMEOUT_S = 2.0

log = logging.getLogger(__name__)


def pool_view(config: Config, bus: Bus) -> dict[str, Any]:
    """The pool's workers and its robots' cameras, as the tokens say now."""
    pool = Keys(config.detector.pool_prefix or config.stack.prefix)
    bad: list[str] = []

    def refused(key: str, error: Exception) -> None:
        log.warning("dropped bad announcement on %s: %s", key, error)
        bad.append(f"{key}: {error}")

    workers: dict[str, dict[str, Any]] = {}
    for worker, announced in workers_now(bus, pool, TOKENS_TIMEOUT_S, refused).items():
        a = announced[-1]
        served_robots = sorted(a.prefixes or (pool.prefix,))
        workers[worker] = {"capacity_hz": round(a.capacity_hz, 1), "robots": served_robots}
    serving: dict[str, set[str]] = defaultdict(set)
    for key in bus.live_tokens(pool.all_pool_serving(), TOKENS_TIMEOUT_S):
        token = pool.pool_serving_parts(key)
        if token is not None:
            serving[token[0]].add(token[2])
    for worker, info in workers.items():
        info["cameras"] = sorted(serving.get(worker, ()))
    prefixes = set(config.detector.prefixes or (config.stack.prefix,))
    prefixes.update(r for info in workers.values() for r in info["robots"])
    robots: dict[str, dict[str, Any]] = {}
    unserved = []
    for prefix in sorted(prefixes):
        cameras: dict[str, Any] = {}
        for camera, heard in cameras_now(bus, Keys(prefix), TOKENS_TIMEOUT_S, refused).items():
            name = pool_name(prefix, camera, pool.prefix)
            by = sorted(w for w, cams in serving.items() if name in cams)
            cameras[camera] = {"rate_hz": heard[-1].rate_hz, "served_by": ", ".join(by)}
            if not by:
                unserved.append(name)
        robots[prefix] = dict(sorted(cameras.items()))
    return {
        "pool_prefix": pool.prefix,
        "workers": workers,
        "robots": robots,
        "unserved": unserved,
        "bad_announcements": bad,
    }
