"""A unicycle's motion (a differential-drive base), exactly integrated. Pure.

Used by the simulator's base (simworld/world.py) and by the controller's depth memory,
which moves what it saw by the commands it sent (depthscan/local_map.py).
"""

from __future__ import annotations

import math

Pose = tuple[float, float, float]  # x, y, heading (rad, counter-clockwise; REP 103)


def advance(pose: Pose, v: float, w: float, dt: float) -> Pose:
    """``pose`` after moving at ``v`` (m/s forward) and ``w`` (rad/s) for ``dt`` seconds, the
    heading left unwrapped (0 or less ``dt``: ``pose`` as it is)."""
    x, y, th = pose
    if dt <= 0:
        return pose
    if abs(w) > 1e-9:
        r = v / w
        return (
            x + r * (math.sin(th + w * dt) - math.sin(th)),
            y - r * (math.cos(th + w * dt) - math.cos(th)),
            th + w * dt,
        )
    return x + v * dt * math.cos(th), y + v * dt * math.sin(th), th
