"""The detector pool's assignment rule: which live worker serves which camera. Pure: no bus, no
clock. Shared by the workers (services/detector/pool.py, which says how the pool works) and by
whoever audits the pool (common/pool_audit.py, run by the workers and the metrics service).

Rendezvous (highest-random-weight) hashing with bounded loads. Each camera ranks the live
workers by a stable hash of (camera, worker) (blake2b: the same on every host and run, unlike
Python's salted ``hash``). Cameras are placed heaviest first (ties by name); each goes to the
highest-ranked worker whose load plus the camera's weight stays within ``balance`` x (total
weight / live workers), or, when none has room, to the least-loaded worker. A camera's weight
is its pixel rate (``rate_hz`` x width x height, normalised to sum to 1), so that one worker
does not get all the heavy cameras.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Mapping
from typing import Protocol


class CameraRate(Protocol):
    """What the rule reads of a camera's settings (services/camera/contract.py)."""

    @property
    def resize(self) -> tuple[int, int]: ...

    @property
    def rate_hz(self) -> float: ...


#: The pixel count assumed for a camera that keeps its source's size (``resize = [0, 0]``):
#: the stack's config cannot know it before the first frame, and VGA is the common case.
DEFAULT_PIXELS = 640 * 480
_EPS = 1e-9  # float slack on the load bound: weights are sums of normalised fractions


def camera_weights(cameras: Mapping[str, CameraRate]) -> dict[str, float]:
    """Each camera's share of the pixels per second all ``cameras`` send (summing to 1)."""
    raw = {}
    for name, cam in cameras.items():
        width, height = cam.resize
        raw[name] = cam.rate_hz * (width * height if width and height else DEFAULT_PIXELS)
    total = sum(raw.values())
    return {name: w / total for name, w in raw.items()}


def rank(camera: str, worker: str) -> int:
    """``worker``'s stable rendezvous score for ``camera`` (higher is preferred)."""
    digest = hashlib.blake2b(f"{camera}\0{worker}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big")


def assign(
    workers: Iterable[str] | Mapping[str, float], weights: Mapping[str, float], balance: float
) -> dict[str, str]:
    """``{camera: worker}`` for every camera of ``weights`` over the live ``workers``. Empty
    when there is no worker. ``balance`` >= 1 is the slack over a share exactly in proportion
    to capacity that a worker may take before a camera goes to its next choice.

    ``workers`` is either the live workers' names (all of equal capacity) or ``{worker:
    capacity}`` (common/messages.py's ``WorkerAnnouncement.capacity_hz``; > 0): each worker's
    bound is ``balance`` x total weight x its capacity / the total capacity, so a worker twice
    as fast takes about twice the load. A camera none has room for goes to the worker whose
    load after it, against its capacity, is least (ties: the better-ranked)."""
    capacity = (
        {w: float(c) for w, c in workers.items()}
        if isinstance(workers, Mapping)
        else dict.fromkeys(workers, 1.0)
    )
    live = sorted(capacity)
    if not live:
        return {}
    if balance < 1:
        raise ValueError(f"balance must be at least 1, got {balance}")
    if any(not c > 0 for c in capacity.values()):
        raise ValueError(f"every capacity must be above 0, got {capacity}")
    total_cap = sum(capacity.values())
    total = sum(weights.values())
    bound = {w: balance * total * capacity[w] / total_cap + _EPS for w in live}
    load = dict.fromkeys(live, 0.0)
    out: dict[str, str] = {}
    for camera in sorted(weights, key=lambda c: (-weights[c], c)):
        weight = weights[camera]
        ranked = sorted(live, key=lambda w: (-rank(camera, w), w))
        chosen = next((w for w in ranked if load[w] + weight <= bound[w]), None)
        if chosen is None:
            chosen = min(ranked, key=lambda w: (load[w] + weight) / capacity[w])
        load[chosen] += weight
        out[camera] = chosen
    return out
