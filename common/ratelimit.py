"""Log lines that a flood cannot multiply: the first few per key, then one summary per period.

Pure: the clock is injected, nothing is logged here; the caller logs what :meth:`admit` says.
Counting is the caller's job too, and is never limited: the log only says *that* input was
dropped and why, the counters say *how much*.
"""

from __future__ import annotations

import threading
from collections import Counter, OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

from common.clock import mono_s

#: Lines logged in full per key before the limiter starts summarising.
LOG_BURST = 5
#: At most one summary line per key per this many seconds while a flood lasts.
LOG_PERIOD_S = 10.0
#: Keys remembered (the least recently seen are forgotten first): garbage on many keys, or
#: made-up reasons, cannot grow the table.
MAX_KEYS = 256
#: Distinct reasons named in one summary; the rest are summed under "other".
MAX_REASONS = 8


@dataclass(frozen=True, slots=True)
class Admit:
    """What to log for one event: the event's own line (``log``), and before it a summary of
    what was suppressed since the last one (``summary``, or "")."""

    log: bool
    summary: str = ""


@dataclass(slots=True)
class _KeyState:
    window_start: float
    last_seen: float
    logged: int = 0
    suppressed: Counter[str] = field(default_factory=Counter)


class LogLimiter:
    """Per key (a key expression, a counter name ...): the first ``burst`` events are logged in
    full; after that, events are only tallied by reason, and the next event at least
    ``period_s`` after the window opened brings a summary line with those tallies. A key quiet
    for a whole period starts afresh, so the next incident is logged in full again.
    Thread-safe: Zenoh callbacks and the service loop share one limiter."""

    def __init__(
        self,
        burst: int = LOG_BURST,
        period_s: float = LOG_PERIOD_S,
        clock: Callable[[], float] = mono_s,
        max_keys: int = MAX_KEYS,
    ) -> None:
        if burst < 0 or period_s <= 0 or max_keys < 1:
            raise ValueError("burst >= 0, period_s > 0 and max_keys >= 1 are required")
        self.burst = burst
        self.period_s = period_s
        self._clock = clock
        self._max_keys = max_keys
        self._keys: OrderedDict[str, _KeyState] = OrderedDict()
        self._lock = threading.Lock()

    def admit(self, key: str, reason: str) -> Admit:
        """Note one event on ``key`` for ``reason``; say what to log for it."""
        now = self._clock()
        with self._lock:
            state = self._keys.get(key)
            if state is None or (not state.suppressed and now - state.last_seen >= self.period_s):
                state = _KeyState(window_start=now, last_seen=now)
                self._keys[key] = state
                while len(self._keys) > self._max_keys:
                    self._keys.popitem(last=False)
            self._keys.move_to_end(key)
            state.last_seen = now
            if state.logged < self.burst:
                state.logged += 1
                return Admit(log=True)
            summary = ""
            if state.suppressed and now - state.window_start >= self.period_s:
                summary = self._summary(key, state, now)
            if not state.suppressed:
                state.window_start = now
            state.suppressed[reason if len(state.suppressed) < MAX_REASONS else "other"] += 1
            return Admit(log=False, summary=summary)

    def due(self) -> list[str]:
        """Summaries of the keys whose period is over with events suppressed: for a caller's
        timer, so that the summary of a flood that stopped is not left waiting for the next
        event."""
        now = self._clock()
        with self._lock:
            return [
                self._summary(k, s, now)
                for k, s in self._keys.items()
                if s.suppressed and now - s.window_start >= self.period_s
            ]

    def drain(self) -> list[str]:
        """Summaries of everything suppressed and not yet reported (e.g. at shutdown)."""
        now = self._clock()
        with self._lock:
            return [self._summary(k, s, now) for k, s in self._keys.items() if s.suppressed]

    def _summary(self, key: str, state: _KeyState, now: float) -> str:
        total = sum(state.suppressed.values())
        reasons = ", ".join(f"{r} {n}" for r, n in state.suppressed.most_common())
        line = (
            f"{key}: {total} more not logged in the last {now - state.window_start:.0f} s "
            f"({reasons})"
        )
        state.suppressed = Counter()
        state.window_start = now
        return line
