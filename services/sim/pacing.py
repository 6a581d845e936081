"""The simulator's pace: its world keeps the wall clock's time, as a real robot's does. Pure.

The physics steps ``dt`` at a time. When a pass of the simulator's loop takes longer than one
step (rendering several cameras on a busy CPU), the world takes the steps it is owed before the
next render, up to ``max_steps`` a pass: a world that slowed down instead would be kinder than
the real one (a base turning slower than commanded while the controller, on the wall clock,
predicts its turn) and would hide the controller's latency. Beyond ``max_steps`` the rest is
given up and counted (a CPU so starved that the world does slow down), never run in a burst.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(slots=True)
class Pace:
    """The physics' steps owed on the wall clock: ``dt`` each, at most ``max_steps`` a pass."""

    dt: float
    max_steps: int
    at: float = 0.0  # the wall time (monotonic, s) the world's time has reached
    given_up_s: float = 0.0  # the time the world fell behind and did not catch up

    def start(self, now: float) -> None:
        """The world's clock starts now."""
        self.at = now

    def due(self, now: float) -> int:
        """How many steps to take at ``now``: those owed since the last pass (0 for a pass
        early by less than a step), at most ``max_steps``; the rest is given up (counted in
        ``given_up_s``: the world then runs slower than the wall clock)."""
        owed = max(0, int((now - self.at) / self.dt + 1e-9))
        steps = min(owed, self.max_steps)
        self.at += steps * self.dt
        if now - self.at >= self.dt:
            self.given_up_s += now - self.at
            self.at = now
        return steps
