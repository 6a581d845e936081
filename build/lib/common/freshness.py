"""Is a message fresh enough to act on? Pure: headers and stamps in, a verdict out.

Three ways a message can be unfit, each counted under its own name by the caller:

- ``stale``:  captured longer ago than the limit;
- ``future``: stamped ahead of the receiver's clock by more than the tolerance (a clock that
  is wrong, or a forged stamp; either way the age cannot be known);
- ``replay``: not newer than the last message accepted from the same source (the same
  message sent again, or an old one recorded and played back).

Age is judged on the wall clock and, when sender and receiver share a boot of one host, on the
monotonic clock as well; the verdict takes the worse of the two, so a wall clock that steps
can stop the robot but never make old data look new.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from enum import StrEnum

from common.clock import Stamp
from common.messages import Header

MAX_SOURCES = 64  # distinct sources remembered for the replay check (oldest forgotten first)


class Verdict(StrEnum):
    FRESH = "fresh"
    STALE = "stale"
    FUTURE = "future"
    REPLAY = "replay"


def ages_s(header: Header, now: Stamp, boot_id: str) -> tuple[float, ...]:
    """The message's age in seconds on every clock both ends share (wall, maybe monotonic)."""
    wall = (now.wall_ns - header.stamp_ns) / 1e9
    if header.mono_ns > 0 and boot_id and header.boot_id == boot_id:
        return wall, (now.mono_ns - header.mono_ns) / 1e9
    return (wall,)


def capture_age_s(header: Header, now: Stamp, boot_id: str) -> float:
    """The larger of the ages: what a safety check must assume."""
    return max(ages_s(header, now, boot_id))


def judge_age(
    header: Header, now: Stamp, boot_id: str, max_age_s: float, future_tolerance_s: float
) -> tuple[Verdict, float]:
    """``stale``, ``future`` or ``fresh``, with the age a caller should use (>= 0)."""
    ages = ages_s(header, now, boot_id)
    if min(ages) < -future_tolerance_s:
        return Verdict.FUTURE, max(ages)
    age = max(0.0, max(ages))
    if age > max_age_s:
        return Verdict.STALE, age
    return Verdict.FRESH, age


@dataclass
class FreshnessGate:
    """Judges each arriving message and remembers, per source, the newest it accepted.

    A source is the header's ``source`` on one boot; messages from one source are ordered by
    their monotonic stamp when they carry one (it never steps back), else by the wall stamp.
    """

    max_age_s: float
    future_tolerance_s: float
    boot_id: str

    def __post_init__(self) -> None:
        self._newest: OrderedDict[tuple[str, str], int] = OrderedDict()

    def check(self, header: Header, now: Stamp) -> tuple[Verdict, float]:
        """The verdict for ``header``; only a fresh message is remembered as accepted."""
        verdict, age = judge_age(header, now, self.boot_id, self.max_age_s, self.future_tolerance_s)
        if verdict is not Verdict.FRESH:
            return verdict, age
        source = (header.source, header.boot_id)
        order = header.mono_ns if header.mono_ns > 0 else header.stamp_ns
        newest = self._newest.get(source)
        if newest is not None and order <= newest:
            return Verdict.REPLAY, age
        self._newest[source] = order
        self._newest.move_to_end(source)
        while len(self._newest) > MAX_SOURCES:
            self._newest.popitem(last=False)
        return Verdict.FRESH, age
