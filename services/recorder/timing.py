"""A replay's clock: when each recorded message is due, and the stamps it is given. Pure.

A pass starts at ``start`` (now, on both clocks); a message recorded ``d`` after the first one
of the pass is due ``d / rate`` after ``start``. Its new capture stamp keeps the lag it had
between capture and recording (transport, a few ms), bounded by ``MAX_LAG_NS``, so that a bag
whose header stamps come from another clock (simulated time) is stamped as if captured when
recorded. Stamps are never ahead of the moment the message is due, so the freshness rules
(common/freshness.py) accept them as live: not stale, not from the future, and newer each time.
"""

from __future__ import annotations

from dataclasses import dataclass

from common.clock import Stamp

MAX_LAG_NS = 500_000_000  # a capture-to-record lag beyond this is a clock mismatch, not a delay


@dataclass(frozen=True, slots=True)
class Schedule:
    rate: float
    start: Stamp
    first_log_ns: int

    def __post_init__(self) -> None:
        if not self.rate > 0:
            raise ValueError(f"the rate must be positive, got {self.rate}")

    def due(self, log_ns: int) -> Stamp:
        """When the message recorded at ``log_ns`` is to be published."""
        offset = round(max(0, log_ns - self.first_log_ns) / self.rate)
        return Stamp(self.start.wall_ns + offset, self.start.mono_ns + offset)

    def restamp(self, log_ns: int, stamp_ns: int) -> Stamp:
        """The new capture stamp of a message captured at ``stamp_ns``, recorded at ``log_ns``."""
        if not 0 <= log_ns - stamp_ns <= MAX_LAG_NS:
            return self.due(log_ns)
        # due(log_ns) less the lag over the rate, in one rounding: equal stamps, equal results.
        offset = round((stamp_ns - self.first_log_ns) / self.rate)
        return Stamp(self.start.wall_ns + offset, self.start.mono_ns + offset)
