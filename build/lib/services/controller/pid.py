"""A PID controller with output and integral limits. Pure: the caller passes dt."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class PIDGains:
    """Gains and limits. The integral is clamped so a long saturation cannot wind it up."""

    kp: float
    ki: float = 0.0
    kd: float = 0.0
    output_limit: float = float("inf")
    integral_limit: float = float("inf")


class PID:
    """``u = kp*e + ki*integral(e) + kd*de/dt``, clipped to +-output_limit."""

    def __init__(self, gains: PIDGains) -> None:
        self.gains = gains
        self._integral = 0.0
        self._previous: float | None = None

    def reset(self) -> None:
        """Forget the history, e.g. when the target changes or the robot was stopped."""
        self._integral = 0.0
        self._previous = None

    def update(self, error: float, dt: float) -> float:
        g = self.gains
        derivative = 0.0
        if dt > 0:
            self._integral += error * dt
            lim = g.integral_limit
            self._integral = min(max(self._integral, -lim), lim)
            if self._previous is not None:
                derivative = (error - self._previous) / dt
        self._previous = error
        u = g.kp * error + g.ki * self._integral + g.kd * derivative
        return min(max(u, -g.output_limit), g.output_limit)
