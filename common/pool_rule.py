"""The detector pool's assignment rule: which live worker serves which camera. Pure: no bus, no
clock. Shared by the workers (services/detector/pool.py, which says how the pool works) and by
whoever audits the pool (common/pool_audit.py, run by the workers and the metrics service).

Rendezvous (highest-random-weight) hashing with bounded loads. Each camera ranks the live
workers by a stable hash of (camera, worker) (blake2b: the same on every host and run, unlike
Python's salted ``hash``). Cameras are placed heaviest first (ties by name); each goes to the
highest-ranked worker whose load plus the camera's weight stays within its bound, ``balance`` x
the total weight x the worker's share of the capacity, or, when none has room, to the worker
whose load after it, against its capacity, is least. A camera's weight is the frame rate it
announces (``CameraAnnouncement.rate_hz``), a worker's capacity the frame rate it can detect
(``WorkerAnnouncement.capacity_hz``): one unit, frames per second, so that a worker twice as
fast takes about twice the frames.

A pool may serve several robots (key prefixes): :func:`assign_pool` divides each robot's
cameras among the live workers that list its prefix, robot by robot, each worker with its
capacity split evenly among the robots it lists (:func:`robot_capacity`). Robot by robot,
because a worker hears only the cameras of the robots it lists (under the secure profile it may
read nothing else), yet every worker that serves a robot must compute that robot's owners
alike: from that robot's cameras and the workers' announcements, nothing of the other robots.
One pass over every robot's cameras would need every robot's cameras in every view. The even
split keeps a worker that lists two robots to about its capacity's share of the whole pool's
load (a whole share for each robot would make it take a full share of each, twice its own);
its cost: a worker that lists a robot with no cameras keeps that robot's part of its capacity
unused, as far as the bound goes (``balance`` and the fallback below still place every camera).

Only how many cameras of each weight each worker takes comes from the capacities; the cameras
are then placed by rank within those numbers, so a capacity that moves without changing them
moves no camera (issue 39). A member dropped from a robot for delivering nothing
(common/pool_delivery.py) is left out of that robot's placement (``assign_pool``'s
``excluded``). Which announced cameras are placed at all is :func:`admit_cameras`'s. A worker
name announced by two sessions at once counts with the lowest capacity claimed
(:func:`one_worker`).

A camera's name in the pool (:func:`pool_name`) is its bare name when it is announced under the
pool's own prefix (one robot: the names of its config), else ``<prefix>/<camera>``; in counter
names (``serving.<camera>``) that reads ``<prefix>:<camera>`` (:func:`label`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass
from typing import Protocol

_EPS = 1e-9  # float slack on the load bound


class CameraRate(Protocol):
    """What :func:`camera_rates` reads of a camera's settings (services/camera/contract.py)."""

    @property
    def rate_hz(self) -> float: ...


@dataclass(frozen=True, slots=True)
class PoolCamera:
    """A camera as the pool sees it: the robot ``prefix`` it is announced under, its name
    there and the frames per second it announces (its weight)."""

    prefix: str
    camera: str
    rate_hz: float
    hfov_deg: float = 0.0  # its announced field of view (0: not known); the rule ignores it


@dataclass(frozen=True, slots=True)
class PoolWorker:
    """A live worker as the pool sees it: the frames per second it can detect and the robot
    prefixes whose cameras it serves."""

    capacity_hz: float
    prefixes: frozenset[str]


def pool_name(prefix: str, camera: str, pool_prefix: str) -> str:
    """``camera`` of robot ``prefix``'s name in the pool under ``pool_prefix``: bare for the
    pool's own robot, ``<prefix>/<camera>`` for another's (a key chunk path: serving tokens)."""
    return camera if prefix == pool_prefix else f"{prefix}/{camera}"


def label(name: str) -> str:
    """A pool name as it reads in a counter's name (``frames_in.<label>``, split at the last
    dot: common/counters.py): ``robot2/front`` is ``robot2:front``; a bare name is itself."""
    if "/" not in name:
        return name
    return name.replace(".", "_").replace("/", ":")


def robot_of(camera_label: str) -> str:
    """The robot part of a camera's :func:`label` ("" for a camera of the pool's own robot):
    ``robot2:front`` is of ``robot2``. A bare name never holds a ':' (a key chunk's letters)."""
    return camera_label.rpartition(":")[0]


def robot_label(prefix: str, pool_prefix: str) -> str:
    """Robot ``prefix``'s part in its cameras' labels (:func:`robot_of`)."""
    return robot_of(label(pool_name(prefix, "camera", pool_prefix)))


def camera_rates(cameras: Mapping[str, CameraRate]) -> dict[str, float]:
    """Each configured camera's weight, its ``rate_hz`` (for who audits a config's cameras)."""
    return {name: cam.rate_hz for name, cam in cameras.items()}


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
    load after it, against its capacity, is least (ties: the better-ranked). That pass fixes
    only how many cameras of each weight each worker takes; the cameras are then placed by
    rank within those numbers (:func:`_place`), so that a capacity that moves without
    changing them moves no camera."""
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
    # How many cameras of each weight each worker takes: the capacities' only say.
    quota: dict[tuple[str, float], int] = {}
    for camera in sorted(weights, key=lambda c: (-weights[c], c)):
        weight = weights[camera]
        ranked = sorted(live, key=lambda w: (-rank(camera, w), w))
        chosen = next((w for w in ranked if load[w] + weight <= bound[w]), None)
        if chosen is None:
            chosen = min(ranked, key=lambda w: (load[w] + weight) / capacity[w])
        load[chosen] += weight
        quota[chosen, weight] = quota.get((chosen, weight), 0) + 1
    return _place(live, weights, quota)


def _place(
    live: list[str], weights: Mapping[str, float], quota: dict[tuple[str, float], int]
) -> dict[str, str]:
    """Each camera to its best-ranked worker with room left in its ``quota`` of that weight
    (every camera finds one: the quotas of a weight sum to its cameras). The capacities reach
    the placement only through the quotas, so a capacity that moves without changing how many
    cameras of each weight each worker takes moves no camera (issue 39)."""
    out: dict[str, str] = {}
    for camera in sorted(weights, key=lambda c: (-weights[c], c)):
        weight = weights[camera]
        ranked = sorted(live, key=lambda w: (-rank(camera, w), w))
        chosen = next(w for w in ranked if quota.get((w, weight), 0) > 0)
        quota[chosen, weight] -= 1
        out[camera] = chosen
    return out


def one_worker(claims: Iterable[PoolWorker]) -> PoolWorker:
    """What a worker name counts as when several live announcements of it are heard at once
    (two sessions announcing one name: a second process with the name's credentials, a raw
    session; a moment's overlap of a re-announcement too): the **lowest** capacity any of them
    claims, and the robots **any** of them lists. Both from the set of live announcements,
    never from the order they came in (which differs from one listener to another), so every
    worker, the name's own included, and every metrics service reach one assignment. A claim
    under a held name can thus never win cameras the name's first holder would not serve
    (issue 39): it can only lower the name's share, which the others take; a robot it adds is
    judged by delivery (common/pool_delivery.py). ``claims`` must not be empty."""
    claims = list(claims)
    if not claims:
        raise ValueError("one_worker needs at least one announcement")
    return PoolWorker(
        min(c.capacity_hz for c in claims), frozenset().union(*(c.prefixes for c in claims))
    )


def robot_capacity(worker: PoolWorker) -> float:
    """The part of ``worker``'s capacity that the rule gives each robot it lists: an even
    split (the module's docstring says why)."""
    return worker.capacity_hz / max(1, len(worker.prefixes))


def assign_pool(
    workers: Mapping[str, PoolWorker],
    cameras: Mapping[str, PoolCamera],
    balance: float,
    excluded: Collection[tuple[str, str]] = (),
) -> dict[str, str]:
    """``{pool name: worker}`` for the ``cameras`` (by pool name) of every robot prefix that
    a live worker lists: each robot's cameras by :func:`assign` among the workers that list
    its prefix, each with its :func:`robot_capacity`, but those ``(prefix, worker)`` of
    ``excluded`` (dropped from that robot for not delivering: common/pool_delivery.py). A
    camera of a robot no worker lists has no owner. Never every worker of a robot: when the
    only ones left that list it are excluded (the others left the pool since), they all serve
    it, as a worker alone is never dropped. With one robot this is :func:`assign` over the
    workers' capacities."""
    out: dict[str, str] = {}
    for prefix in sorted({c.prefix for c in cameras.values()}):
        listing = {w: robot_capacity(p) for w, p in workers.items() if prefix in p.prefixes}
        eligible = {w: c for w, c in listing.items() if (prefix, w) not in excluded} or listing
        rates = {n: c.rate_hz for n, c in cameras.items() if c.prefix == prefix}
        out.update(assign(eligible, rates, balance))
    return out


def counter_key(name: str) -> str:
    """What a camera's pool name reads as in counter names once a ``.`` (where a counter's
    name is split, common/counters.py) and a ``_`` are told apart no more: two cameras with
    one such key (``cam.x`` and ``cam_x``) would share their counters and slot."""
    return label(name).replace(".", "_")


def admit_cameras(
    cameras: Mapping[str, PoolCamera], max_per_robot: int
) -> tuple[dict[str, PoolCamera], dict[str, str]]:
    """The announced ``cameras`` (by pool name) the pool serves, and those it refuses with
    why: of names whose :func:`counter_key` collides, the first by name is kept; of one
    robot's cameras, the first ``max_per_robot`` by name. Pure and by name only, so every
    worker and auditor admits the same."""
    kept: dict[str, PoolCamera] = {}
    refused: dict[str, str] = {}
    taken: dict[str, str] = {}
    per_robot: dict[str, int] = {}
    for name in sorted(cameras):
        cam = cameras[name]
        key = counter_key(name)
        if key in taken:
            refused[name] = f"its counter label {key} is camera {taken[key]}'s too"
            continue
        if per_robot.get(cam.prefix, 0) >= max_per_robot:
            refused[name] = (
                f"robot {cam.prefix} announces over {max_per_robot} cameras "
                "(detector.max_robot_cameras)"
            )
            continue
        taken[key] = name
        per_robot[cam.prefix] = per_robot.get(cam.prefix, 0) + 1
        kept[name] = cam
    return kept, refused
