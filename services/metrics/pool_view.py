"""``zstack pool --config FILE``: the whole detector pool as one host sees it, from its tokens
alone (no metrics service needed: a GPU box runs none). Each worker's announcement (capacity,
robots) and the cameras it serves; each robot's announced cameras (rate) and who serves each,
those nobody serves listed. The pool is ``detector.pool_prefix`` (empty: ``stack.prefix``);
its robots are those the workers announce and the config's ``detector.prefixes``."""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from common.announce import from_chunk
from common.bus import Bus
from common.errors import DecodeError
from common.keys import Keys
from common.messages import CameraAnnouncement, WorkerAnnouncement
from common.pool_rule import pool_name
from stack.config import Config

TOKENS_TIMEOUT_S = 2.0


def pool_view(config: Config, bus: Bus) -> dict[str, Any]:
    """The pool's workers and its robots' cameras, as the tokens say now."""
    pool = Keys(config.detector.pool_prefix or config.stack.prefix)
    workers: dict[str, dict[str, Any]] = {}
    for key in bus.live_tokens(pool.all_worker_announcements(), TOKENS_TIMEOUT_S):
        parts = pool.worker_announcement_parts(key)
        try:
            a = from_chunk(WorkerAnnouncement.decode, parts[1]) if parts else None
        except DecodeError:
            a = None
        if a is not None:
            served_robots = sorted(a.prefixes or (pool.prefix,))
            workers[a.worker] = {"capacity_hz": round(a.capacity_hz, 1), "robots": served_robots}
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
        keys = Keys(prefix)
        cameras: dict[str, Any] = {}
        for key in bus.live_tokens(keys.all_camera_announcements(), TOKENS_TIMEOUT_S):
            parts = keys.camera_announcement_parts(key)
            try:
                c = from_chunk(CameraAnnouncement.decode, parts[1]) if parts else None
            except DecodeError:
                c = None
            if parts is None or c is None:
                continue
            name = pool_name(prefix, parts[0], pool.prefix)
            by = sorted(w for w, cams in serving.items() if name in cams)
            cameras[parts[0]] = {"rate_hz": c.rate_hz, "served_by": ", ".join(by)}
            if not by:
                unserved.append(name)
        robots[prefix] = dict(sorted(cameras.items()))
    return {"pool_prefix": pool.prefix, "workers": workers, "robots": robots, "unserved": unserved}
