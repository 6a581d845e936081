"""Velocity and acceleration limits on a (linear, angular) command. Pure."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Limits:
    """Speeds in m/s and rad/s, accelerations in m/s^2 and rad/s^2."""

    max_linear: float
    max_angular: float
    max_linear_accel: float
    max_angular_accel: float


def _clip(x: float, lim: float) -> float:
    return min(max(x, -lim), lim)


def limit(
    previous: tuple[float, float], desired: tuple[float, float], dt: float, lim: Limits
) -> tuple[float, float]:
    """The command closest to ``desired`` within the speed limits and reachable from
    ``previous`` in ``dt`` seconds under the acceleration limits."""
    v = _clip(desired[0], lim.max_linear)
    w = _clip(desired[1], lim.max_angular)
    if dt <= 0:
        return previous
    v = previous[0] + _clip(v - previous[0], lim.max_linear_accel * dt)
    w = previous[1] + _clip(w - previous[1], lim.max_angular_accel * dt)
    return v, w
