"""The camera's log of skipped frames (unreadable files, oversized images), rate limited.

A folder with a few corrupt files is read over and over: logging each skip would write a line
per corrupt file per pass, forever. The first :data:`FIRST_LOGGED` skips are logged one by one;
after that one summary line per :data:`SUMMARY_PERIOD_S` says how many more were skipped. The
count itself is exact (the service's ``bad_images`` counter); only the log is thinned.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

#: Skips logged one by one before the log turns to periodic summaries.
FIRST_LOGGED = 3
#: At most one summary line per this many seconds while skips go on.
SUMMARY_PERIOD_S = 30.0


class SkipLog:
    """Logs skipped frames: the first few each on a line, then a summary per period."""

    def __init__(
        self,
        log: logging.Logger,
        *,
        first_logged: int = FIRST_LOGGED,
        period_s: float = SUMMARY_PERIOD_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._log = log
        self._first_logged = first_logged
        self._period_s = period_s
        self._clock = clock
        self.total = 0
        self._pending = 0  # skipped since the last line that reported them
        self._last_error = ""
        self._summary_at = 0.0

    def skip(self, error: Exception) -> None:
        """Note one skipped frame, and log it if it is among the first or a summary is due."""
        self.total += 1
        if self.total <= self._first_logged:
            more = " (further skips are summarised)" if self.total == self._first_logged else ""
            self._log.warning("skipped: %s%s", error, more)
            self._summary_at = self._clock() + self._period_s
            return
        self._pending += 1
        self._last_error = str(error)
        if self._clock() >= self._summary_at:
            self.flush()

    def flush(self) -> None:
        """Log the summary of the skips not reported yet (at the end, or when one is due)."""
        if not self._pending:
            return
        self._log.warning(
            "skipped %d more unreadable frame(s) (%d in all); the latest: %s",
            self._pending,
            self.total,
            self._last_error,
        )
        self._pending = 0
        self._summary_at = self._clock() + self._period_s
