"""The detector pool as the metrics service sees it: who is live and serves which camera, from
the pool's liveliness tokens (:class:`LivePool`), and what is wrong with it (common/pool_audit.py);
each worker's load and hand-overs from its counters; frames detected twice. Pure: no bus, no
clock.

A worker (``detector``, ``detector_<n>``) holds a pool token while in the pool and a serving
token per camera it serves; it counts ``serving.<cam>`` (1 while it serves the camera),
``pool_load_permille``, ``pool_members``, ``cameras_gained`` and ``cameras_lost``
(services/detector/membership.py::PoolMember). The tokens go when the worker does (at once when
it exits or is killed, after Zenoh's lease when it hangs), so they, not the counters (a dead
worker's last word), say who serves a camera.

One worker never detects a frame twice (a frame leaves its camera's slot once), so a second
Detections for the same camera and the same frame (its header's boot id, sequence number and
capture stamp) comes from another worker: the overlap of a hand-over, while the old owner has
not yet heard that it lost the camera. :class:`Duplicates` counts them.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping

from common.contracts import WorkerMetrics
from common.counters import per_camera
from common.messages import Header
from common.pool_audit import PoolAudit, Report, Serving
from common.pool_delivery import Delivery
from common.pool_rule import PoolCamera, PoolWorker, admit_cameras, assign_pool, pool_name
from common.settings import service_package
from services.detector import contract as detector

RECENT_FRAMES = 256  # frames remembered per camera: a hand-over's overlap is well under this


class Duplicates:
    """Frames seen twice, per camera (bounded memory: the last :data:`RECENT_FRAMES` each)."""

    def __init__(self) -> None:
        self.per_camera: dict[str, int] = {}
        self._seen: dict[str, tuple[deque[tuple[str, int, int]], set[tuple[str, int, int]]]] = {}

    @property
    def total(self) -> int:
        return sum(self.per_camera.values())

    def seen(self, camera: str, header: Header) -> bool:
        """Note ``camera``'s frame ``header``; True when it was already seen (a duplicate)."""
        order, known = self._seen.setdefault(camera, (deque(), set()))
        frame = (header.boot_id, header.seq, header.stamp_ns)
        if frame in known:
            self.per_camera[camera] = self.per_camera.get(camera, 0) + 1
            return True
        order.append(frame)
        known.add(frame)
        if len(order) > RECENT_FRAMES:
            known.discard(order.popleft())
        return False


class LivePool:
    """The pool's tokens as heard now: its members and their serving tokens, and the audit of
    them (:meth:`check`; ``report`` is the latest). Not thread-safe: the caller holds its lock.

    The metrics service of robot ``robot`` in a pool under ``pool_prefix`` (common/pool_rule.py;
    both "": one robot, its own pool) audits what the workers compute: its robot's cameras as
    announced (``cameras``: ``{camera: rate_hz}``; None: the audit's configured weights) and
    the members as they announce themselves (``announced``: capacity and robots; a pool token
    without an announcement is no member, as the workers count). The serving tokens name
    cameras by their pool name; what the answer shows is this robot's cameras only, by their
    own names.

    With ``delivery`` (common/pool_delivery.py; :meth:`saw` notes each camera's detections),
    it judges who delivers as the workers do (the cameras admitted as they admit them, at most
    ``max_robot_cameras``), and the audit warns of a member dropped for delivering nothing and
    of a camera whose detections do not come, whatever the tokens say."""

    def __init__(
        self,
        audit: PoolAudit,
        robot: str = "",
        pool_prefix: str = "",
        delivery: Delivery | None = None,
        max_robot_cameras: int = 1024,
    ) -> None:
        self.audit = audit
        self.delivery = delivery
        self.max_robot_cameras = max_robot_cameras
        self.robot = robot
        self.pool_prefix = pool_prefix
        self.members: set[str] = set()
        self.servers: set[Serving] = set()
        self.announced: dict[str, PoolWorker] = {}
        self.announcements: dict[str, int] = {}  # live announcements per name (2: twice)
        self.cameras: dict[str, float] | None = None
        self.heard = False  # a pool token was ever heard: the tokens, not counters, decide
        self.report = Report()

    def pool_name(self, camera: str) -> str:
        """This robot's ``camera`` as the pool names it (in serving tokens)."""
        return pool_name(self.robot, camera, self.pool_prefix)

    def own(self, name: str) -> str | None:
        """The camera of this robot that pool name ``name`` is; None for another robot's."""
        if self.robot == self.pool_prefix:
            return None if "/" in name else name
        head = f"{self.robot}/"
        rest = name[len(head) :]
        return rest if name.startswith(head) and rest and "/" not in rest else None

    def member(self, worker: str, *, live: bool) -> None:
        self.heard = True
        if live:
            self.members.add(worker)
        else:
            self.members.discard(worker)
            if self.delivery is not None:
                self.delivery.left(worker)  # a process that comes back is judged afresh

    def serving(self, token: Serving, *, live: bool) -> None:
        self.heard = True
        if live:
            self.servers.add(token)
        else:
            self.servers.discard(token)

    def check(self, now: float) -> Report:
        if self.cameras is None:
            self.report = self.audit.check(now, self.members, self.servers)
        else:
            members = {m: self.announced[m] for m in self.members if m in self.announced}
            if not self.announced:  # none readable (an access rule without them): as before,
                members = {m: PoolWorker(1.0, frozenset({self.robot})) for m in self.members}
            announced = {
                self.pool_name(c): PoolCamera(self.robot, c, rate)
                for c, rate in self.cameras.items()
            }
            cameras, _ = admit_cameras(announced, self.max_robot_cameras)
            delivery = self.delivery
            if delivery is None:
                self.report = self.audit.check(
                    now, members, self.servers, cameras=cameras, announcements=self.announcements
                )
                return self.report
            delivery.forget(cameras)
            excluded = delivery.excluded(now)
            owners = assign_pool(members, cameras, self.audit.balance, excluded)
            delivery.judge(now, owners, cameras, members)
            self.report = self.audit.check(
                now,
                members,
                self.servers,
                cameras=cameras,
                dropped=delivery.dropped,
                undelivered=delivery.undelivered(now, cameras),
                announcements=self.announcements,
            )
        return self.report

    def saw(self, camera: str, now: float, worker: str = "") -> None:
        """A detection of this robot's ``camera`` made by ``worker`` arrived at ``now``."""
        if self.delivery is not None and self.cameras is not None and camera in self.cameras:
            self.delivery.saw(self.pool_name(camera), now, worker)

    def served_by(self, camera: str) -> str:
        """The live workers serving ``camera`` (", "-joined when two do: a warning)."""
        name = self.pool_name(camera)
        return ", ".join(sorted({w for w, _, c in self.servers if c == name}))

    def cameras_of(self, worker: str) -> set[str]:
        """The cameras of this robot that ``worker`` serves (another robot's are not shown)."""
        own = (self.own(c) for w, _, c in self.servers if w == worker)
        return {c for c in own if c is not None}


def workers(
    counters: Mapping[str, int],
    cameras: Iterable[str],
    reported_at: Mapping[str, float],
    now: float,
    pool: LivePool | None = None,
) -> dict[str, WorkerMetrics]:
    """Each detector worker that counts ``serving``, from ``counters`` (``<service>.<name>``
    -> value) and when its counters last came (``reported_at``); with ``pool`` (its tokens
    heard), whether it is live and the cameras it serves come from its tokens: a worker that
    has gone (exited, killed, hung past Zenoh's lease) is ``live: false`` and serves nothing."""
    cams = list(cameras)
    out: dict[str, WorkerMetrics] = {}
    for service in sorted(reported_at):
        if (
            service_package(service) != "detector"
            or f"{service}.{detector.SERVING}" not in counters
        ):
            continue
        if pool is not None and pool.heard:
            live = service in pool.members
            served = pool.cameras_of(service)
            mine = [c for c in cams if c in served] + sorted(served - set(cams))
        else:
            live = True
            mine = [
                c
                for c in cams
                if counters.get(f"{service}.{per_camera(detector.SERVING, c)}", 0) > 0
            ]
        out[service] = WorkerMetrics(
            live=live,
            cameras=mine,
            load=counters.get(f"{service}.{detector.POOL_LOAD_PERMILLE}", 0) / 1000.0,
            members=counters.get(f"{service}.{detector.POOL_MEMBERS}", 0),
            cameras_gained=counters.get(f"{service}.{detector.CAMERAS_GAINED}", 0),
            cameras_lost=counters.get(f"{service}.{detector.CAMERAS_LOST}", 0),
            reported_s_ago=max(0.0, now - reported_at[service]),
            load_from="counters",
        )
    if pool is not None:
        _remote_workers(out, cams, pool)
    return out


def _remote_workers(out: dict[str, WorkerMetrics], cams: list[str], pool: LivePool) -> None:
    """Add to ``out`` the live pool members serving this robot whose counters it does not
    hear (another host's worker, counting under its own prefix: a shared GPU box), from
    their tokens and announcements; and each listed worker's announced capacity and robots."""
    rates = pool.cameras or {}
    for worker in sorted(pool.members):
        announced = pool.announced.get(worker)
        served = pool.cameras_of(worker)
        mine = [c for c in cams if c in served] + sorted(served - set(cams))
        if worker not in out and (served or (announced and pool.robot in announced.prefixes)):
            capacity = announced.capacity_hz if announced else 0.0
            load = sum(rates.get(c, 0.0) for c in mine) / capacity if capacity > 0 else 0.0
            out[worker] = WorkerMetrics(
                live=True, cameras=mine, load=round(load, 3), members=0, cameras_gained=0,
                cameras_lost=0, reported_s_ago=-1.0, load_from="cameras",
            )  # fmt: skip
    for worker, metrics in out.items():
        announced = pool.announced.get(worker)
        if announced is not None:
            metrics["capacity_hz"] = round(announced.capacity_hz, 1)
            metrics["robots"] = sorted(announced.prefixes)
