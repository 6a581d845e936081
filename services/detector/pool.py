"""Which detector worker serves which camera: the pool's assignment rule. Pure: no bus, no clock.

A pool has no coordinator. Every worker hears the same bus view and computes the same
assignment from it with common/pool_rule.py's :func:`assign_pool`, so the workers agree on who
serves which camera without talking:

- the members: a worker is one while it holds both its pool token ``<pool>/detector/pool/
  <worker>`` and its announcement ``<pool>/detector/workers/<worker>/<chunk>`` (a
  WorkerAnnouncement: its capacity and the robot prefixes it serves). A token without an
  announcement (a raw session's, a stray) is no member: it cannot take cameras nobody serves;
- the cameras: those announced (CameraAnnouncement) under each robot prefix the workers serve,
  each weighed by its announced frame rate, never a worker's own config.

The rule (common/pool_rule.py, shared with whoever audits the pool): rendezvous hashing with
loads bounded in proportion to each worker's capacity, robot by robot, a worker's capacity
split evenly among the robots it lists (so that one serving two robots takes its share of the
pool, not a share of each; and each robot's owners follow from that robot's cameras alone,
all that a worker listing only that robot hears).

A member earns its cameras (common/pool_delivery.py): one none of whose cameras of a robot
gets detections within ``detector.pool_deliver_s`` is left out of that robot's placement
(``excluded``) for a while, whatever capacity it announces. Only how many cameras of each
weight each worker takes comes from the capacities, so a capacity change that keeps those
numbers moves no camera. A name announced by two sessions at once (a second process with its
credentials) counts with the lowest capacity claimed (common/pool_rule.py's ``one_worker``), so
a claim under another's name wins no camera the name's holder would not serve.

What follows (tests/unit/detector/test_pool.py): every camera has exactly one owner; a
worker that joins takes about its share and no more; a worker that leaves hands on only its
own cameras while the others' loads allow (a camera whose first choice is full goes to the
next, so a tight ``balance`` can move a few more).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from common.pool_rule import PoolCamera, PoolWorker, assign, assign_pool, rank

__all__ = ["Change", "PoolCamera", "PoolView", "PoolWorker", "assign", "assign_pool", "rank"]


@dataclass(frozen=True, slots=True)
class Change:
    """What one worker must do after the pool changed: serve ``gained``, stop serving
    ``lost`` (pool names); ``serving`` is all it now serves (``cameras``: each one's robot
    and name there), ``load`` their share (0..1) of the frame rate of every camera it hears,
    and ``members`` how many live workers it counted."""

    gained: tuple[str, ...]
    lost: tuple[str, ...]
    serving: frozenset[str]
    load: float
    members: int
    cameras: Mapping[str, PoolCamera] = field(default_factory=dict)


class PoolView:
    """One worker's view of the pool: the pool tokens and worker announcements heard, the
    announced cameras and the cameras it serves. It is always a member itself, as ``mine``
    says (its own announcement). Not thread-safe: the caller holds its lock."""

    def __init__(self, me: str, mine: PoolWorker, balance: float) -> None:
        self.me = me
        self.mine = mine
        self.balance = balance
        self.tokens: set[str] = set()
        self.announced: dict[str, PoolWorker] = {}
        self.cameras: dict[str, PoolCamera] = {}
        self.serving: frozenset[str] = frozenset()
        #: (robot prefix, worker) dropped from that robot's assignment for not delivering
        #: (common/pool_delivery.py); the rule places no camera of the robot on them.
        self.excluded: frozenset[tuple[str, str]] = frozenset()
        self.owners: dict[str, str] = {}  # the whole assignment, as the last settle made it
        #: How many live announcements of each name are heard (two: a name held twice).
        self.announcements: dict[str, int] = {}

    @property
    def members(self) -> dict[str, PoolWorker]:
        """The live members: a pool token and an announcement each; itself always."""
        out = {w: self.announced[w] for w in self.tokens if w in self.announced}
        out[self.me] = self.mine
        return out

    def strays(self) -> list[str]:
        """Pool tokens with no announcement: ignored (no member)."""
        return sorted(w for w in self.tokens if w not in self.announced and w != self.me)

    def joined(self, worker: str) -> None:
        self.tokens.add(worker)

    def left(self, worker: str) -> None:
        if worker != self.me:  # our own token's loss is the lease's news, not a resignation
            self.tokens.discard(worker)

    def settle(self) -> Change:
        """Recompute the assignment; what changed for this worker."""
        owners = assign_pool(self.members, self.cameras, self.balance, self.excluded)
        self.owners = owners
        serving = frozenset(c for c, w in owners.items() if w == self.me)
        total = sum(c.rate_hz for c in self.cameras.values())
        change = Change(
            gained=tuple(sorted(serving - self.serving)),
            lost=tuple(sorted(self.serving - serving)),
            serving=serving,
            load=sum(self.cameras[c].rate_hz for c in serving) / total if total else 0.0,
            members=len(self.members),
            cameras={c: self.cameras[c] for c in serving},
        )
        self.serving = serving
        return change
