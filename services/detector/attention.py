"""Attention when short of capacity (:class:`Attention`): which cameras a round takes first.

A camera has *priority* while it holds the controller's lock (the ``camera`` of its latest
ControllerStatus, heard within ``hold_s``) or while it saw one of the controller's target
classes (the status's ``target_classes``) within ``hold_s``. With no camera prioritised the
order is the slots' fair one, untouched (services/detector/schedule.py). With priorities, a
round takes, in this order:

1. the cameras *due* for their floor (the one due longest first), so that no camera is ever
   left unwatched for long (a priority camera that is due is taken here too, and counted as
   priority);
2. the priority cameras, longest-waiting first;
3. the others, longest-waiting first (spare capacity: only when no priority camera waits).

A camera is due once ``1 / floor_hz`` s have passed since it was last taken. The guarantee
(docs/detector.md, "Attention"): **a camera with frames coming is taken at least every
``1 / floor_hz + ceil(n / max_batch) * R`` s** (plus one frame interval: its next frame may
come just after it fell due), ``n`` the cameras and ``R`` one round's time, and its detections
are as far apart: once due, at most the ``n - 1`` others due before it go ahead of it, each
once, and every round takes the ``max_batch`` due longest; **as long as the floors fit**: while
they take at most ``floor_share`` of the frames the rounds take. Against the controller: with
the defaults (1.5 Hz, 0.67 s) that bound stays under its dead-man, ``controller.
detection_timeout_s`` (1 s), while ``ceil(n / max_batch) * R`` is under 0.33 s (three cameras
at 0.1 s a round): an empty camera's detections then never age past it before the next one
comes. When the floors would take more (many cameras on a slow worker), the priority cameras go
first and the floors have what is left (counted: ``attention_floor_held``), so the target's
camera keeps at least ``1 - floor_share`` of the rounds, and the floor's bound no longer
holds: an empty camera's detections may then age past the dead-man between two, and the
controller ignores them as stale meanwhile (it never drives on them). A person stepping into
an empty camera's view is detected within the bound plus one round ``R`` (the frame taken is
the newest, the detection one round later; the controller acts on the first detection, no
confirmation frames), and that camera has priority from then on.

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
#: The weight of each round in the moving average of the share of its frames the floors take.
ROUND_WEIGHT = 0.1


class Attention:
    """Priorities and the floor rate (see the module's docstring); ``enabled`` False leaves
    every round in the fair order."""

    def __init__(
        self,
        clock: Clock,
        floor_hz: float,
        hold_s: float,
        enabled: bool = True,
        *,
        floor_share: float = 1.0,
    ):
        if floor_hz <= 0 or hold_s < 0 or not 0 < floor_share <= 1:
            raise ValueError(
                f"floor_hz must be > 0, hold_s >= 0 and floor_share in (0, 1], "
                f"got {floor_hz}, {hold_s}, {floor_share}"
            )
        self.clock = clock
        self.period_s = 1.0 / floor_hz
        self.hold_s = hold_s
        self.enabled = enabled
        self.floor_share = floor_share
        #: Rounds in which the due cameras went after the priority ones (the floors over
        #: their share); the loop's, read by services/detector/rounds.py.
        self.floor_held = 0
        self._floor_frac = 0.0  # the share of the frames taken for the floor, moving average
        self._reasons: dict[str, str] = {}  # the last arrangement's reasons
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
                self._reasons = {}
                return [(cam, "") for cam in cameras]
            due_at = {cam: self._taken.get(cam, -math.inf) + self.period_s for cam in cameras}
            due = sorted((c for c in cameras if due_at[c] <= now), key=due_at.__getitem__)
            held = self._floor_frac > self.floor_share and any(c not in first for c in due)
            if held:
                self.floor_held += 1
        rest = [c for c in cameras if c not in due]
        if held:  # the floors over their share: the priority cameras first
            out = (
                [(c, PRIORITY) for c in due if c in first]
                + [(c, PRIORITY) for c in rest if c in first]
                + [(c, FLOOR) for c in due if c not in first]
                + [(c, SPARE) for c in rest if c not in first]
            )
        else:
            out = (
                [(c, PRIORITY if c in first else FLOOR) for c in due]
                + [(c, PRIORITY) for c in rest if c in first]
                + [(c, SPARE) for c in rest if c not in first]
            )
        with self._lock:
            self._reasons = dict(out)
        return out

    def taken(self, cameras: Sequence[str]) -> None:
        """``cameras`` were taken in a round now: their floor's period starts again."""
        now = self.clock.mono_s()
        with self._lock:
            for cam in cameras:
                self._taken[cam] = now
            if self._reasons and cameras:
                floors = sum(1 for c in cameras if self._reasons.get(c) == FLOOR)
                self._floor_frac += ROUND_WEIGHT * (floors / len(cameras) - self._floor_frac)
