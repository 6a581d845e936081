"""Whether the detector pool's members deliver what they are given (issue 39): a member earns its
cameras by their detections arriving, not by the capacity it claims or the serving tokens it
holds. Pure: no bus, no clock (times are given).

Everyone who audits or computes the pool (each worker, each robot's metrics service) hears every
camera's detections on the bus (``<robot>/detector/<camera>/detections``) and notes each
one's arrival and the worker it names (:meth:`Delivery.saw`): a member is judged on the
detections it made, not on any of its cameras' (a judge that heard the member given a camera
later than the others did would otherwise take the real worker's, once it took the camera
back, for the member's). A member is **not delivering** when none
of the cameras the rule gives it has had a detection for ``detector.pool_deliver_s`` since the
member was given it (or since that camera's last detection, whichever is later). Such a member
is **dropped**, robot by robot (a member given cameras of two robots is judged on each robot's
apart, as every judge of a robot hears that robot's detections alike): the rule places that
robot's cameras without it (common/pool_rule.py), for
``detector.pool_readmit_s`` the first time, twice as long each further time (at most
:data:`MAX_READMIT_DOUBLINGS` doublings), after which it is given cameras again and must
deliver on one of them within the bound. A member that delivers again is forgiven its strikes.
A member whose pool token goes (a process that exits, is killed or restarted) has its drops
lifted: the process that comes back under its name is judged afresh, as a worker that joins
later, which knows nothing of past drops, would judge it.

Every judge decides from what it hears on the bus alike (the detections of each camera, the
members and their announcements), so the workers agree on who is dropped up to the moment
each one hears a detection: a hand-over's moment, as when a member leaves.

Never everyone: a judgment that would drop the last members (a robot whose cameras all stopped
sending frames: no worker can deliver on them) drops none of them, as one worker alone in the
pool is never dropped. A member judged on a camera whose frames stopped coming while its other
cameras deliver is not dropped (some of its cameras deliver): the audit's ``unserved`` says
which camera gets no detections (common/pool_audit.py).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from common.pool_rule import PoolCamera, PoolWorker

#: A member dropped again and again waits ``pool_readmit_s`` x 2**k, k at most this.
MAX_READMIT_DOUBLINGS = 5


#: A member as judged for one robot: (robot prefix, worker).
Judged = tuple[str, str]


@dataclass(frozen=True, slots=True)
class Dropped:
    """A member dropped from one robot's assignment (``robot``: its prefix) for not
    delivering: since when, until when, and the cameras it was given and delivered none of."""

    robot: str
    worker: str
    since: float
    until: float
    cameras: tuple[str, ...]


class Delivery:
    """The detections heard per camera and the members dropped for not delivering (see the
    module's docstring). Not thread-safe: the caller holds its lock."""

    def __init__(self, deliver_s: float, readmit_s: float) -> None:
        if deliver_s <= 0 or readmit_s <= 0:
            raise ValueError(f"deliver_s and readmit_s must be > 0, got {deliver_s}, {readmit_s}")
        self.deliver_s = deliver_s
        self.readmit_s = readmit_s
        self._last: dict[str, float] = {}  # camera -> its last detection heard at
        self._anon: dict[str, float] = {}  # camera -> its last detection naming no worker
        # (camera, worker) -> the last detection of a camera given to it that it made
        self._by: dict[tuple[str, str], float] = {}
        self._given: dict[tuple[str, str], float] = {}  # (camera, worker) -> given since
        self._strikes: dict[Judged, int] = {}
        self._asked: dict[str, float] = {}  # camera -> first asked about (undelivered)
        self.dropped: dict[Judged, Dropped] = {}

    def saw(self, camera: str, now: float, worker: str = "") -> None:
        """A detection of ``camera`` (its pool name) arrived at ``now``, made by ``worker``
        (its Detections' ``worker``; "": a writer that names none, which counts for whoever
        is given the camera, as every detection did before). A named one counts only for
        that worker, and only while it is given the camera: the last detection of the
        camera's former owner, still on its way, or a real worker's taking a camera back from
        a member that holds it and delivers nothing, is no evidence for that member."""
        self._last[camera] = now
        if not worker:
            self._anon[camera] = now
        elif (camera, worker) in self._given:
            self._by[camera, worker] = now

    def forget(self, cameras: Iterable[str]) -> None:
        """Only ``cameras`` are announced now: forget the others' detections (bounded)."""
        keep = set(cameras)
        for known in (self._last, self._asked, self._anon):
            for camera in [c for c in known if c not in keep]:
                del known[camera]
        self._by = {pair: at for pair, at in self._by.items() if pair[0] in keep}

    def left(self, worker: str) -> None:
        """``worker``'s pool token went (it exited, was killed, resigned or its lease ran
        out): a token that comes back is a new process, which a worker that joins then knows
        nothing against: its drops and its strikes are lifted, so that every view agrees (a
        judge that joins later would otherwise readmit it sooner after its next drop)."""
        for judged in [j for j in self.dropped if j[1] == worker]:
            del self.dropped[judged]
        for judged in [j for j in self._strikes if j[1] == worker]:
            del self._strikes[judged]
        self._given = {pair: at for pair, at in self._given.items() if pair[1] != worker}

    def excluded(self, now: float) -> frozenset[Judged]:
        """The (robot, member) pairs dropped at ``now`` (those whose time is over are
        readmitted)."""
        for judged in [j for j, d in self.dropped.items() if now >= d.until]:
            del self.dropped[judged]
        return frozenset(self.dropped)

    def note(
        self, now: float, owners: Mapping[str, str], cameras: Mapping[str, PoolCamera]
    ) -> None:
        """The assignment now (``owners``, ``{camera: worker}``): a camera given to a worker
        that did not have it starts that worker's bound on it."""
        self._given = {
            (c, w): self._given.get((c, w), now) for c, w in owners.items() if c in cameras
        }  # fmt: skip
        self._by = {pair: at for pair, at in self._by.items() if pair in self._given}

    def judge(
        self,
        now: float,
        owners: Mapping[str, str],
        cameras: Mapping[str, PoolCamera],
        members: Mapping[str, PoolWorker],
    ) -> list[Dropped]:
        """Note who is given which camera (``owners``, ``{camera: worker}``, as the rule
        placed them without the dropped members; ``cameras``: each one's robot) and drop, robot
        by robot, the members that deliver on none of theirs within the bound; those dropped
        now. ``members``: the live members (the dropped ones too): never every member that
        lists a robot is dropped from it."""
        self.note(now, owners, cameras)
        evidence: dict[Judged, float] = {}
        given: dict[Judged, list[str]] = {}
        for (camera, worker), since in self._given.items():
            judged = (cameras[camera].prefix, worker)
            last = max(self._by.get((camera, worker), -math.inf),
                       self._anon.get(camera, -math.inf))  # fmt: skip
            evidence[judged] = max(evidence.get(judged, -math.inf), since, last)
            given.setdefault(judged, []).append(camera)
            if last > since:
                self._strikes.pop(judged, None)  # it delivers: forgiven
        out = []
        for judged, at in sorted(evidence.items()):
            robot, worker = judged
            if now - at <= self.deliver_s or judged in self.dropped:
                continue
            standing = [
                w for w, p in members.items()
                if robot in p.prefixes and (robot, w) not in self.dropped and w != worker
            ]  # fmt: skip
            if not standing:
                continue  # never everyone: nobody could take over
            strikes = self._strikes.get(judged, 0)
            self._strikes[judged] = strikes + 1
            wait = self.readmit_s * 2 ** min(strikes, MAX_READMIT_DOUBLINGS)
            drop = Dropped(robot, worker, now, now + wait, tuple(sorted(given[judged])))
            self.dropped[judged] = drop
            out.append(drop)
            for camera in drop.cameras:  # readmitted, it is given them afresh
                del self._given[camera, worker]
        return out

    def undelivered(self, now: float, cameras: Iterable[str]) -> dict[str, float]:
        """Those of ``cameras`` whose last detection is over ``deliver_s`` old (or none came
        since they were first asked about), with how long they have had none."""
        out = {}
        for camera in cameras:
            since = self._asked.setdefault(camera, now)  # first asked: its bound starts
            age = now - max(since, self._last.get(camera, -math.inf))
            if age > self.deliver_s:
                out[camera] = age
        return out
