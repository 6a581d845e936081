"""What is wrong with the detector pool, as anyone who hears its liveliness tokens can tell. Pure:
no bus, no clock.

A member of the pool is a worker holding a token on ``<pool>/detector/pool/<name>`` and an
announcement (WorkerAnnouncement) under ``<pool>/detector/workers/<name>/``: a token alone is
ignored. Each worker serves what the rule (common/pool_rule.py) gives it from the cameras
announced on the bus. Each worker also declares, for every camera it serves, a token
``<pool>/detector/serving/<worker>/<zenoh id>/<camera>`` (common/keys.py). From both, each
worker and the metrics service audit the pool (:class:`PoolAudit`) and warn when, for longer
than ``detector.pool_alarm_s``:

- ``idle_member``: a member serves none of the cameras the rule gives it (a hung worker, one
  that has not yet heard a camera's announcement);
- ``unserved``: a camera of this table has no worker serving it (none live at all, too), or
  no detections of it arrived for ``detector.pool_deliver_s`` whatever the serving tokens say
  (common/pool_delivery.py: a camera is served when its detections arrive);
- ``undelivering``: a member was dropped from the pool for delivering no detections on the
  cameras the rule gave it (common/pool_delivery.py);
- ``served_twice``: a camera is served by two workers (or two processes of one name);
- ``name_twice``: one worker name is held by two processes (two hosts with one ``worker_id``),
  as their serving tokens show, or announced by two sessions at once (a second process with
  the name's credentials: the pool counts the name with the lowest capacity claimed,
  common/pool_rule.py's ``one_worker``).

A hand-over makes some of these true for a moment (the old and the new owner settle apart):
only what lasts past the alarm time is reported.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from common.pool_delivery import Dropped, Judged
from common.pool_rule import PoolCamera, PoolWorker, assign_pool

#: A serving token's parts: (worker, zenoh id of its session, camera).
Serving = tuple[str, str, str]
KINDS = ("idle_member", "unserved", "served_twice", "name_twice", "undelivering")
#: The most findings said one by one (in a log at once, or in an answer): a raw session can
#: declare thousands of tokens, and the rest is one line that counts them.
MAX_LINES = 20


@dataclass(frozen=True, slots=True)
class Finding:
    """One thing wrong: its ``kind`` (one of :data:`KINDS`), what it is about (a worker or a
    camera) and since when it has held."""

    kind: str
    subject: str
    detail: str
    since: float

    def text(self, now: float) -> str:
        return f"{self.detail} for {now - self.since:.0f} s"


@dataclass(slots=True)
class Report:
    """The findings held past the alarm time (``current``), and those that became so
    (``raised``) or stopped (``cleared``) since the previous check."""

    current: list[Finding] = field(default_factory=list)
    raised: list[Finding] = field(default_factory=list)
    cleared: list[Finding] = field(default_factory=list)

    def count(self, kind: str) -> int:
        return sum(1 for f in self.current if f.kind == kind)


def lines(findings: list[Finding], now: float, limit: int = MAX_LINES) -> list[str]:
    """Each finding's text, at most ``limit`` of them, then one line for the rest."""
    out = [f.text(now) for f in findings[:limit]]
    if len(findings) > limit:
        out.append(f"and {len(findings) - limit} more findings about the pool")
    return out


class PoolAudit:
    """Checks the pool's tokens against the rule and remembers since when each finding holds.
    The cameras and members are given to :meth:`check` as heard (announced cameras by pool
    name, members with their announced capacity and prefixes); without them, the cameras are
    ``weights`` (``{camera: rate_hz}``, one robot) and the members of equal capacity. Not
    thread-safe: the caller holds its lock."""

    def __init__(self, weights: Mapping[str, float], balance: float, alarm_s: float) -> None:
        self.weights = dict(weights)
        self.balance = balance
        self.alarm_s = alarm_s
        self._since: dict[tuple[str, str], float] = {}
        self._raised: dict[tuple[str, str], Finding] = {}

    def check(
        self,
        now: float,
        members: Iterable[str] | Mapping[str, PoolWorker],
        serving: Iterable[Serving],
        *,
        cameras: Mapping[str, PoolCamera] | None = None,
        dropped: Mapping[Judged, Dropped] | None = None,
        undelivered: Mapping[str, float] | None = None,
        announcements: Mapping[str, int] | None = None,
    ) -> Report:
        """The findings at ``now`` for the live ``members`` (names, or each one's capacity
        and prefixes as announced) and ``serving`` tokens, over ``cameras`` (by pool name; by
        default ``weights``); ``dropped``: the members dropped for not delivering, which the
        rule places no camera on; ``undelivered``: the cameras whose detections have not
        come for the delivery bound, with how long (common/pool_delivery.py);
        ``announcements``: how many live announcements of each worker name are heard (two
        sessions announcing one name: ``name_twice``)."""
        serving = set(serving)
        if cameras is None:
            cameras = {c: PoolCamera("", c, w) for c, w in self.weights.items()}
        if not isinstance(members, Mapping):
            robots = frozenset(c.prefix for c in cameras.values())
            members = {m: PoolWorker(1.0, robots) for m in members}
        found_list = _findings(members, serving, cameras, self.balance, dropped or {})
        found_list += _announced_twice(members, set(serving), announcements or {})
        findings = found_list + _undelivered(
            now, members, serving, cameras, dropped or {}, undelivered or {}
        )
        found = {(f.kind, f.subject): f.detail for f in findings}
        self._since = {k: self._since.get(k, now) for k in found}
        report = Report()
        for key, detail in sorted(found.items()):
            if now - self._since[key] < self.alarm_s:
                continue
            finding = Finding(kind=key[0], subject=key[1], detail=detail, since=self._since[key])
            report.current.append(finding)
            if key not in self._raised:
                report.raised.append(finding)
            self._raised[key] = finding
        for key in [k for k in self._raised if k not in found]:
            report.cleared.append(self._raised.pop(key))
        return report


@dataclass(frozen=True, slots=True)
class _Found:
    kind: str
    subject: str
    detail: str


def _findings(
    members: Mapping[str, PoolWorker],
    serving: Iterable[Serving],
    cameras: Mapping[str, PoolCamera],
    balance: float,
    dropped: Mapping[Judged, Dropped],
) -> list[_Found]:
    live = sorted(members)
    by_camera: dict[str, set[tuple[str, str]]] = {}
    by_worker: dict[str, set[str]] = {}
    for worker, zid, camera in set(serving):
        by_camera.setdefault(camera, set()).add((worker, zid))
        by_worker.setdefault(worker, set()).add(zid)
    owners = assign_pool(members, cameras, balance, dropped.keys())
    out: list[_Found] = []
    for worker in live:
        given = sorted(c for c, w in owners.items() if w == worker)
        if given and worker not in by_worker:
            out.append(_Found("idle_member", worker, (
                f"pool member {worker} serves none of the cameras the pool gives it "
                f"({', '.join(given)}): a hung worker, or one that does not hear them"
            )))  # fmt: skip
    for camera in cameras:  # no live worker at all: every camera unserved, said so
        if camera not in by_camera:
            owner = owners.get(camera)
            why = (
                f" (the pool gives it to {owner})" if owner
                else " (no live detector worker)" if not live
                else " (no worker serves its robot)"
            )  # fmt: skip
            out.append(
                _Found("unserved", camera, f"camera {camera} is served by no detector worker{why}")
            )
    for camera, servers in sorted(by_camera.items()):
        if len(servers) > 1 and camera in cameras:  # another table's camera is not ours
            names = ", ".join(f"{w} ({z})" for w, z in sorted(servers))
            out.append(_Found("served_twice", camera, (
                f"camera {camera} is served by {len(servers)} workers at once: {names}; "
                "do they hear different pools or cameras?"
            )))  # fmt: skip
    for worker, zids in sorted(by_worker.items()):
        if len(zids) > 1:
            out.append(_Found("name_twice", worker, (
                f"worker name {worker} is held by {len(zids)} processes (zenoh ids "
                f"{', '.join(sorted(zids))}): give each host its own detector.worker_id"
            )))  # fmt: skip
    return out


def _announced_twice(
    members: Mapping[str, PoolWorker], serving: Iterable[Serving], announcements: Mapping[str, int]
) -> list[_Found]:
    """A member's name announced by several sessions at once (said once: by the serving
    tokens' zenoh ids when those show it already)."""
    zids: dict[str, set[str]] = {}
    for worker, zid, _ in serving:
        zids.setdefault(worker, set()).add(zid)
    twice_by_tokens = {w for w, z in zids.items() if len(z) > 1}
    out = []
    for worker, n in sorted(announcements.items()):
        if n > 1 and worker in members and worker not in twice_by_tokens:
            out.append(_Found("name_twice", worker, (
                f"worker name {worker} is announced by {n} sessions at once (another process "
                "with its name or credentials?): the pool counts it with the lowest capacity "
                "announced"
            )))  # fmt: skip
    return out


def _undelivered(
    now: float,
    members: Mapping[str, PoolWorker],
    serving: Iterable[Serving],
    cameras: Mapping[str, PoolCamera],
    dropped: Mapping[Judged, Dropped],
    undelivered: Mapping[str, float],
) -> list[_Found]:
    """What the detections that arrive (not the tokens) say: the members dropped for
    delivering nothing, and the cameras with a serving token whose detections do not come."""
    out: list[_Found] = []
    robots = {c.prefix for c in cameras.values()}
    for (robot, worker), drop in sorted(dropped.items()):
        if worker in members and robot in robots:
            out.append(_Found("undelivering", f"{robot}/{worker}", (
                f"pool member {worker}, dropped from the pool ({drop.until - now:.0f} s more), "
                "whatever capacity it announces, delivered no detections on the cameras the "
                f"pool gave it ({', '.join(drop.cameras[:MAX_LINES])})"
            )))  # fmt: skip
    tokens: dict[str, set[str]] = {}
    for worker, _, camera in set(serving):
        tokens.setdefault(camera, set()).add(worker)
    for camera in sorted(undelivered):
        if camera in cameras and camera in tokens:  # none at all: said above
            out.append(_Found("unserved", camera, (
                f"camera {camera} is served by no detector worker (no detections of it arrive, "
                f"though {', '.join(sorted(tokens[camera]))} holds its serving token)"
            )))  # fmt: skip
    return out
