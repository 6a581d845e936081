"""The robot's pose by its own commands, for a stage that must know how it moved between two
instants (the depth scan's memory, the tracker's ego-rotation). Pure: times are handed in."""

from __future__ import annotations

import math
import threading
from collections import deque

from common.unicycle import Pose, advance


class Odometry:
    """The robot's pose by its own commands (thread-safe): each command holds until the next.
    ``history_s`` of commands are kept, so a frame captured that long ago is placed. It
    starts at ``start`` (a pose restored with the map: :meth:`LocalMap.restore`)."""

    def __init__(self, history_s: float = 10.0, start: Pose = (0.0, 0.0, 0.0)) -> None:
        self._lock = threading.Lock()
        self._history_s = history_s
        # (time, pose at that time, v, w from then on); the first holds still from -inf.
        self._log: deque[tuple[float, Pose, float, float]] = deque()
        self._log.append((-math.inf, start, 0.0, 0.0))

    def coasted(self, t: float, coast_s: float) -> Pose:
        """Where the robot would be ``coast_s`` after ``t`` if the command in force at ``t``
        went on (as a base does until its own command timeout when the controller dies)."""
        with self._lock:
            _, _, v, w = self._log[-1]
        return advance(self.pose_at(t), v, w, coast_s)

    def command(self, t: float, v: float, w: float) -> None:
        """From monotonic time ``t`` on the robot moves at (``v``, ``w``)."""
        with self._lock:
            t0, pose, v0, w0 = self._log[-1]
            if t < t0:
                return  # out of order: the clock never goes back, a caller might
            self._log.append((t, advance(pose, v0, w0, t - t0 if t0 > -math.inf else 0), v, w))
            while len(self._log) > 2 and self._log[1][0] < t - self._history_s:
                self._log.popleft()

    def pose_at(self, t: float) -> Pose:
        """The pose at monotonic time ``t`` (before the history: its oldest pose)."""
        with self._lock:
            entries = list(self._log)
        for t0, pose, v, w in reversed(entries):
            if t0 <= t:
                return advance(pose, v, w, t - t0) if t0 > -math.inf else pose
        return entries[0][1]
