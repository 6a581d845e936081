"""Attention when short of capacity (:class:`Attention`): which cameras a round takes first.

A camera has *priority* while it holds the controller's lock (the ``camera`` of its latest
ControllerStatus, heard within ``hold_s``) or while it saw one of the controller's target
classes (the status's ``target_classes``) within ``hold_s``. With no camera prioritised the
order is the slots' fair one, untouched (services/detector/schedule.py). With priorities, a
round takes, in this order:

1. the cameras *due* for their floor: not taken for ``1 / floor_hz`` s (the one due longest
   first), so that no camera is ever left unwatched for long (a priority camera that is due
   is taken here too, and counted as priority);
2. the priority cameras, longest-waiting first;
3. the others, longest-waiting first (spare capacity: only when no priority camera waits).

The bound this gives (docs/detector.md, "Attention"): a camera with frames coming is taken at
least every ``1 / floor_hz + ceil(n / max_batch) * R`` s, ``n`` the cameras and ``R`` one
round's time: once due, at most the ``n - 1`` others due before it go ahead of it, each
once, and every round takes the ``max_batch`` due longest. A person stepping into an empty
camera's view is then detected within ``1 / floor_hz + (ceil(n / max_batch) + 1) * R`` s (the
frame taken is the newest, the detection one round later; the controller acts on the first
detection, no confirmation frames), and that camera has priority from then on.

One worker may serve several robots (docs/detector.md, "Several robots"): a camera is known
by its label in the pool (common/pool_rule.py: ``front`` for the pool's own robot,
``robot2:front`` for robot2's), each robot's controller locks one of its own cameras, and a
camera's sightings count against its own robot's target classes.

Pure: time is read from the injected clock; thread-safe (the controller's status arrives on
a bus thread, the loop arranges and notes sightings).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable, Sequence

from common.clock import Clock
from common.pool_rule import robot_of

#: Why a round took a camera where it did (``Waiting.reason``; counted per reason).
PRIORITY = "priority"  # it holds the lock or saw a target class lately
FLOOR = "floor"  # due for its floor rate, ahead of the priority cameras
SPARE = "spare"  # neither: taken only because no priority camera was waiting
REASONS = (PRIORITY, FLOOR, SPARE)


class Attention:
    """Priorities and the floor rate (see the module's docstring); ``enabled`` False leaves
    every round in the fair order."""

    def __init__(self, clock: Clock, floor_hz: float, hold_s: float, enabled: bool = True):
        if floor_hz <= 0 or hold_s < 0:
            raise ValueError(f"floor_hz must be > 0 and hold_s >= 0, got {floor_hz}, {hold_s}")
        self.clock = clock
        self.period_s = 1.0 / floor_hz
        self.hold_s = hold_s
        self.enabled = enabled
        self._lock = threading.Lock()
        # Per robot (common/pool_rule.py's robot_of: "" for the pool's own), from its controller
        self._locked: dict[str, tuple[str, float]] = {}  # robot -> (camera, heard at)
        self._targets: dict[str, frozenset[str]] = {}  # robot -> its target classes
        self._seen: dict[str, dict[str, float]] = {}  # camera -> class -> last seen at
        self._taken: dict[str, float] = {}  # camera -> last taken at

    def controller(self, camera: str, target_classes: Iterable[str], robot: str = "") -> None:
        """A controller's latest status: the camera that sees its target (its label in the
        pool; "" for none) and its target classes; ``robot``: whose controller (the robot
        part of its cameras' labels, "" for the pool's own)."""
        now = self.clock.mono_s()
        with self._lock:
            if camera:
                self._locked[robot] = (camera, now)
            else:
                self._locked.pop(robot, None)
            self._targets[robot] = frozenset(target_classes)

    def saw(self, camera: str, class_names: Iterable[str]) -> None:
        """``camera``'s detections just published named ``class_names``."""
        now = self.clock.mono_s()
        with self._lock:
            seen = self._seen.setdefault(camera, {})
            for name in class_names:
                seen[name] = now

    def priority(self) -> frozenset[str]:
        """The cameras of this worker with priority now (none while disabled)."""
        with self._lock:
            return self._priority(self.clock.mono_s())

    def _priority(self, now: float, waiting: Sequence[str] = ()) -> frozenset[str]:
        """Those of this worker's cameras (taken once, or ``waiting`` now) with priority: in a
        pool the controller's lock may be on a camera another worker serves, which must not
        take this worker's rounds out of their fair order."""
        if not self.enabled:
            return frozenset()
        found = {camera for camera, at in self._locked.values() if now - at <= self.hold_s}
        for camera, seen in self._seen.items():
            targets = self._targets.get(robot_of(camera), frozenset())
            if any(now - seen.get(name, -math.inf) <= self.hold_s for name in targets):
                found.add(camera)
        return frozenset(c for c in found if c in self._taken or c in waiting)

    def arrange(self, cameras: Sequence[str]) -> list[tuple[str, str]]:
        """``cameras`` (longest-waiting first) in the order a round takes them: unchanged
        without priorities, else due, priority, the rest (the module's docstring)."""
        now = self.clock.mono_s()
        with self._lock:
            first = self._priority(now, cameras)
            if not first:
                return [(cam, "") for cam in cameras]
            due_at = {cam: self._taken.get(cam, -math.inf) + self.period_s for cam in cameras}
            due = sorted((c for c in cameras if due_at[c] <= now), key=due_at.__getitem__)
        rest = [c for c in cameras if c not in due]
        return (
            [(c, PRIORITY if c in first else FLOOR) for c in due]
            + [(c, PRIORITY) for c in rest if c in first]
            + [(c, SPARE) for c in rest if c not in first]
        )

    def taken(self, cameras: Sequence[str]) -> None:
        """``cameras`` were taken in a round now: their floor's period starts again."""
        now = self.clock.mono_s()
        with self._lock:
            for cam in cameras:
                self._taken[cam] = now
