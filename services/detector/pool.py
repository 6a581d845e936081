"""Which detector worker serves which camera: the pool's assignment rule. Pure: no bus, no clock.

A pool has no coordinator. Every worker hears the same membership (Zenoh liveliness tokens
``<prefix>/detector/pool/<worker>``, declared in service.py) and computes the same assignment
from it with :func:`assign`, so the workers agree on who serves which camera without talking.

The rule (common/pool_rule.py, shared with whoever audits the pool): rendezvous hashing with
bounded loads, each camera weighted by its pixel rate.

What follows (tests/unit/detector/test_pool.py): every camera has exactly one owner; a
worker that joins takes about its share and no more; a worker that leaves hands on only its
own cameras while the others' loads allow (a camera whose first choice is full goes to the
next, so a tight ``balance`` can move a few more).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from common.pool_rule import DEFAULT_PIXELS, assign, camera_weights, rank

__all__ = ["DEFAULT_PIXELS", "Change", "PoolView", "assign", "camera_weights", "rank"]


@dataclass(frozen=True, slots=True)
class Change:
    """What one worker must do after the membership changed: serve ``gained``, stop serving
    ``lost``; ``serving`` is all it now serves, ``load`` their weight (0..1) and ``members``
    how many live workers it counted."""

    gained: tuple[str, ...]
    lost: tuple[str, ...]
    serving: frozenset[str]
    load: float
    members: int


class PoolView:
    """One worker's view of the pool: the live members (itself always among them) and the
    cameras it serves. Not thread-safe: the caller holds its lock."""

    def __init__(self, me: str, weights: Mapping[str, float], balance: float) -> None:
        self.me = me
        self.weights = dict(weights)
        self.balance = balance
        self.members: set[str] = {me}
        self.serving: frozenset[str] = frozenset()

    def joined(self, worker: str) -> None:
        self.members.add(worker)

    def left(self, worker: str) -> None:
        if worker != self.me:  # our own token's loss is the lease's news, not a resignation
            self.members.discard(worker)

    def settle(self) -> Change:
        """Recompute the assignment from the members; what changed for this worker."""
        owners = assign(self.members, self.weights, self.balance)
        serving = frozenset(c for c, w in owners.items() if w == self.me)
        change = Change(
            gained=tuple(sorted(serving - self.serving)),
            lost=tuple(sorted(self.serving - serving)),
            serving=serving,
            load=sum(self.weights[c] for c in serving),
            members=len(self.members),
        )
        self.serving = serving
        return change
