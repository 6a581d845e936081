"""Fairness between robots (issue 39): a worker serving several robots shares its rounds
between the robots first, then between each robot's cameras (:class:`RobotFair`, an Order of
services/detector/schedule.py).

The fair rounds alone are fair per camera: a robot announcing 61 cameras would take 61 of every
62 rounds from a robot with one. Here each round goes first to the robots with a frame waiting
that were served least lately (a rotation), each robot's own waiting cameras in its own order
(attention's, services/detector/attention.py, or the longest-waiting first). So every robot
with frames waiting gets an equal turn: a robot that sends less than that share gets every
frame it sends (its announced rate, as far as the worker's capacity goes), and what it leaves
goes to the others (max-min fair). The bound: a robot's camera with a frame waiting is taken
within ``ceil(m / max_batch)`` rounds, ``m`` the robots, once it is its robot's first camera;
a robot's one camera (or its target's, with attention) is so within ``ceil(m / max_batch)``
rounds whatever the other robots announce (tests/unit/detector/test_fairness.py).

With one robot the order is the inner one, untouched. A camera's robot is read from its label
in the pool (common/pool_rule.py's ``robot_of``). Not thread-safe: the detection loop alone
takes rounds. Its memory is a number per robot served (at most ``detector.prefixes``).
"""

from __future__ import annotations

from collections.abc import Sequence

from common.pool_rule import robot_of
from services.detector.schedule import Order


class RobotFair:
    """Rounds shared between robots first, then within each robot by ``inner`` (None: the
    longest-waiting first)."""

    def __init__(self, inner: Order | None = None) -> None:
        self.inner = inner
        self._round = 0
        self._served: dict[str, int] = {}  # robot -> the round it was last taken in

    def _within(self, cameras: Sequence[str]) -> list[tuple[str, str]]:
        return [(c, "") for c in cameras] if self.inner is None else self.inner.arrange(cameras)

    def arrange(self, cameras: Sequence[str]) -> list[tuple[str, str]]:
        by_robot: dict[str, list[str]] = {}
        for cam in cameras:
            by_robot.setdefault(robot_of(cam), []).append(cam)
        if len(by_robot) <= 1:
            return self._within(cameras)
        first = {robot: cameras.index(cams[0]) for robot, cams in by_robot.items()}
        robots = sorted(by_robot, key=lambda r: (self._served.get(r, -1), first[r]))
        queues = [self._within(by_robot[r]) for r in robots]
        return [q[i] for i in range(max(map(len, queues))) for q in queues if i < len(q)]

    def taken(self, cameras: Sequence[str]) -> None:
        self._round += 1
        for cam in cameras:
            self._served[robot_of(cam)] = self._round
        if self.inner is not None:
            self.inner.taken(cameras)
