"""A worker's capacity, the frames per second it can detect, as the pool is told it
(services/detector/membership.py announces it). Pure: no bus, no clock (times are given).

Measured at start (:func:`measure`: a few timed rounds after the warm-up) unless the user set
``detector.capacity_hz``, and kept current from the busy rounds' throughput (frames detected /
seconds the round took): a moving average with weight ``detector.capacity_smoothing`` per
round. Announcing a new capacity may move cameras between workers, so :class:`Capacity` says
it is due only when it has stayed more than ``detector.capacity_step`` (a fraction of the one
announced) away from it for ``detector.capacity_period_s`` on end (a hysteresis: a swing of a
busy CPU that comes back within the period is never announced), and that long after the last
announcement. What a new figure may move is bounded too: only a change in how many cameras
each worker takes moves any (common/pool_rule.py).
"""

from __future__ import annotations

from collections.abc import Callable

from common.clock import Clock
from services.detector.contract import MAX_CAPACITY_HZ, DetectorSettings

MIN_CAPACITY_HZ = 0.01  # a worker slower than this still announces this much (must be > 0)


def clamp(hz: float) -> float:
    """``hz`` within what a WorkerAnnouncement may carry."""
    return min(MAX_CAPACITY_HZ, max(MIN_CAPACITY_HZ, hz))


def measure(run_round: Callable[[], int], rounds: int, clock: Clock) -> float:
    """Frames per second over ``rounds`` calls of ``run_round`` (each returns the frames it
    detected), timed on ``clock``."""
    start = clock.mono_s()
    frames = sum(run_round() for _ in range(rounds))
    return clamp(frames / max(clock.mono_s() - start, 1e-6))


class Capacity:
    """The capacity announced and the one measured since. Not thread-safe: the detection
    loop alone calls it."""

    def __init__(self, measured_hz: float, s: DetectorSettings, now_s: float) -> None:
        self.fixed = s.capacity_hz > 0  # the user's: never measured again
        self.current = clamp(s.capacity_hz if self.fixed else measured_hz)
        self.announced = self.current
        self._step = s.capacity_step
        self._period_s = s.capacity_period_s
        self._weight = s.capacity_smoothing
        self._announced_at = now_s
        self._away_since: float | None = None  # since when it has been past the step

    def observe(self, frames: int, seconds: float) -> None:
        """A busy round: ``frames`` detected in ``seconds``."""
        if self.fixed or frames <= 0 or seconds <= 0:
            return
        rate = clamp(frames / seconds)
        self.current += self._weight * (rate - self.current)

    def due(self, now_s: float) -> float | None:
        """The capacity to announce now, when it has stayed more than the step away from the
        one announced for the whole period (a swing that comes back sooner is not announced)
        and the period has passed since the last; else None. Taken as announced."""
        moved = abs(self.current - self.announced) / self.announced
        if moved <= self._step:
            self._away_since = None
            return None
        if self._away_since is None:
            self._away_since = now_s
        if now_s - self._away_since < self._period_s or now_s - self._announced_at < self._period_s:
            return None
        self._away_since = None
        self.announced = self.current
        self._announced_at = now_s
        return self.announced
