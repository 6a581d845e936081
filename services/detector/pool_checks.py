"""What a pool worker checks of the pool (services/detector/membership.py's :class:`PoolMember`
holds one): everyone's serving tokens against the rule (common/pool_audit.py), who delivers the
detections of the cameras they are given (common/pool_delivery.py), and which announced
cameras the pool admits (common/pool_rule.py's ``admit_cameras``). Its words (warnings, gauges)
go out through the node, as do the member's on a change of its cameras (:func:`tell_change`).
Not thread-safe: the member calls it under its own lock, but for the ``tell_*`` functions,
which log and are called outside it.

A member earns its cameras by delivering (common/pool_delivery.py): the worker hears every
camera's detections of the robots it serves and drops from a robot's assignment a member none
of whose cameras of it has had a detection for ``detector.pool_deliver_s`` (counted:
``pool_dropped``, ``pool_drops``). Announced cameras over ``detector.max_robot_cameras`` of a
robot, or whose counter label another's has, are refused (``cameras_refused``)."""

from __future__ import annotations

from collections.abc import Mapping

from common.node import Node
from common.pool_audit import MAX_LINES, PoolAudit, Report, Serving
from common.pool_delivery import Delivery, Dropped, Judged
from common.pool_rule import PoolCamera, admit_cameras
from services.detector import contract
from services.detector.contract import DetectorSettings
from services.detector.counting import count_for
from services.detector.pool import Change, PoolView

AUDIT_PERIOD_S = 0.5  # how often the loop audits the pool's tokens (common/pool_audit.py)


class PoolChecks:
    """The serving tokens heard, the audit, the delivery judge and the admitted cameras of
    one worker's view of the pool."""

    def __init__(self, s: DetectorSettings) -> None:
        self.servers: set[Serving] = set()  # everyone's serving tokens, as heard
        self.audit = PoolAudit({}, s.pool_balance, s.pool_alarm_s)
        self.delivery = Delivery(s.pool_deliver_s, s.pool_readmit_s)
        self.refused: dict[str, str] = {}  # pool name -> why it is refused
        self._max_robot_cameras = s.max_robot_cameras
        self._audit_next = 0.0

    def serving(self, token: Serving, *, alive: bool) -> None:
        if alive:
            self.servers.add(token)
        else:
            self.servers.discard(token)

    def audit_due(self, now: float) -> bool:
        """Whether it is time to audit again (at most every :data:`AUDIT_PERIOD_S`)."""
        if now < self._audit_next:
            return False
        self._audit_next = now + AUDIT_PERIOD_S
        return True

    def check(self, now: float, view: PoolView, mine: set[Serving]) -> Report:
        """The audit of ``view`` with this worker's own serving tokens ``mine``."""
        return self.audit.check(
            now,
            view.members,
            self.servers | mine,
            cameras=view.cameras,
            dropped=self.delivery.dropped,
            undelivered=self.delivery.undelivered(now, view.cameras),
            announcements=view.announcements,
        )

    def admit(self, view: PoolView, announced: Mapping[str, PoolCamera]) -> None:
        """``view``'s cameras: those of ``announced`` the pool admits (the rest refused)."""
        view.cameras, self.refused = admit_cameras(announced, self._max_robot_cameras)
        self.delivery.forget(announced)

    def judge(self, now: float, view: PoolView) -> tuple[list[Dropped], list[Judged]]:
        """Drop from ``view`` the members that deliver nothing, give back those whose time
        is over: those dropped now and those readmitted now (``view.excluded`` follows)."""
        before = view.excluded & frozenset(self.delivery.dropped)  # lifted: no readmission
        self.delivery.excluded(now)
        dropped = self.delivery.judge(now, view.owners, view.cameras, view.members)
        view.excluded = frozenset(self.delivery.dropped)
        return dropped, sorted(before - view.excluded)


def tell_drops(
    node: Node, dropped: list[Dropped], readmitted: list[Judged], deliver_s: float
) -> None:
    """Count and log the members dropped now and those given cameras again."""
    for drop in dropped:
        node.counters.add(contract.POOL_DROPS)
        node.log.warning(
            "pool member %s delivered no detections on %s for %.1f s (detector.pool_deliver_s): "
            "its cameras of %s go to the others for %.0f s, whatever capacity it announces",
            drop.worker,
            ", ".join(drop.cameras[:MAX_LINES]),
            deliver_s,
            drop.robot,
            drop.until - drop.since,
        )
    for robot, worker in readmitted:
        node.log.info("pool member %s is given cameras of %s again", worker, robot)


def tell_change(
    node: Node, change: Change, gained: list[str], lost: list[str], handed_over: bool, told: int
) -> None:
    """Count the cameras ``gained`` and ``lost`` (their labels) when ``handed_over`` (the
    first assignment, at start, is no hand-over), and log the change when a camera moved or
    the pool's size is not the one ``told`` last."""
    if handed_over:
        for cam in gained:
            count_for(node, cam, contract.CAMERAS_GAINED)
        for cam in lost:
            count_for(node, cam, contract.CAMERAS_LOST)
    if change.gained or change.lost or change.members != told:
        node.log.info(
            "pool of %d: serving %s (gained %s, lost %s)",
            change.members,
            sorted(change.serving) or "no camera",
            list(change.gained),
            list(change.lost),
        )


def tell_refused(node: Node, refused: Mapping[str, str], told: Mapping[str, str]) -> None:
    """Log each camera refused now that was not before (``told``)."""
    for name in sorted(refused.keys() - told.keys()):
        node.log.warning("camera %s refused by the pool: %s", name, refused[name])
