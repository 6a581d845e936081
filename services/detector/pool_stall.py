"""A pool worker's stall watch (services/detector/membership.py). A worker whose detection loop
stalls (an inference that never returns, a deadlock) while the bus's threads still keep its
token alive would hold its cameras until the watchdog restarts it. So a thread of its own
(:func:`start_watch`) checks a few times per ``detector.pool_stall_s`` whether the loop beat:
none for ``detector.pool_stall_s`` while other workers are in the pool and the worker
**resigns**, withdrawing its pool token (the others take its cameras at once) and refusing
frames; its next beat declares the token again and it takes its share back. A worker alone in
the pool stays: nobody could take over. One asked to stop (its stop event) resigns at once and
never comes back on its way out (issue 39)."""

from __future__ import annotations

import threading
from collections.abc import Callable

#: The stall watch looks this many times per ``detector.pool_stall_s`` (and at most every
#: :data:`STALL_CHECK_MIN_S`): a stall is noticed within a quarter of the limit after it.
STALL_CHECKS = 4
STALL_CHECK_MIN_S = 0.05


class Stall:
    """The loop's last beat and whether the worker has resigned for a stall. Not thread-safe:
    the member reads and writes it under its own lock."""

    def __init__(self, stall_s: float, now: float) -> None:
        self.stall_s = stall_s
        self.last_beat = now
        self.resigned = False

    def beat(self, now: float, may_return: bool) -> bool:
        """The loop passed at ``now``. True when the worker had resigned and is back now
        (``may_return``: it is neither closed nor asked to stop)."""
        self.last_beat = now
        back = self.resigned and may_return
        if back:
            self.resigned = False
        return back

    def resign(self, others: bool, now: Callable[[], float], stopping: Callable[[], bool]) -> bool:
        """Whether the worker resigns now (and it is then marked resigned): not resigned yet,
        ``others`` in the pool to hand to, and no beat for ``stall_s`` by ``now()`` or on its
        way out (``stopping()``: hand over now, not at close)."""
        stalled = (
            not self.resigned and others and (now() - self.last_beat > self.stall_s or stopping())
        )
        if stalled:
            self.resigned = True
        return stalled


def start_watch(
    check: Callable[[], object], stall_s: float, pause: Callable[[float], bool]
) -> threading.Thread:
    """Call ``check()`` a few times per ``stall_s`` on a thread of its own, until
    ``pause(period)``, the pause between checks, returns True."""
    period = max(STALL_CHECK_MIN_S, stall_s / STALL_CHECKS)

    def watch() -> None:
        while not pause(period):
            check()

    thread = threading.Thread(target=watch, name="pool-stall-watch", daemon=True)
    thread.start()
    return thread
