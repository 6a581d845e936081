"""A plain-text progress bar on stderr for ``detect``: frames done (of the total when known),
frames per second, time left.

Plain text so that it reads well in a CI log: each update is a line of its own (never redrawn
in place, which would also tangle with the results on stdout in a terminal), at most one per
:data:`PROGRESS_PERIOD_S`. The last update (``finish``) is always written.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TextIO

from common.clock import mono_s

#: At most one progress update per this many seconds (the last one is always written).
PROGRESS_PERIOD_S = 1.0
_BAR_WIDTH = 20


def progress_line(label: str, done: int, total: int, elapsed_s: float, unit: str = "frames") -> str:
    """``label: [#####.....]  50% 5/10 frames, 2.0 fps, 3 s left`` (no bar, no total and no time
    left when ``total`` is 0, i.e. unknown, as for a camera)."""
    fps = done / elapsed_s if elapsed_s > 0 else 0.0
    if total <= 0:
        return f"{label}: {done} {unit}, {fps:.1f} fps, {elapsed_s:.0f} s"
    fraction = min(1.0, done / total)
    filled = round(fraction * _BAR_WIDTH)
    bar = "#" * filled + "." * (_BAR_WIDTH - filled)
    if done >= total:
        left = f"done in {elapsed_s:.1f} s"
    elif fps > 0:
        left = f"{(total - done) / fps:.0f} s left"
    else:
        left = "starting"
    return f"{label}: [{bar}] {fraction:4.0%} {done}/{total} {unit}, {fps:.1f} fps, {left}"


class ProgressBar:
    """Throttled progress updates for one input (a video, a device, a list of images)."""

    def __init__(
        self,
        label: str,
        total: int,
        *,
        unit: str = "frames",
        stream: TextIO | None = None,
        period_s: float = PROGRESS_PERIOD_S,
        clock: Callable[[], float] = mono_s,
    ) -> None:
        self._label = label
        self._total = total
        self._unit = unit
        self._stream = sys.stderr if stream is None else stream
        self._period_s = period_s
        self._clock = clock
        self._start = clock()
        self._next = self._start + period_s
        self.done = 0

    def advance(self, n: int = 1) -> None:
        """Count ``n`` more done; write an update if one is due."""
        self.done += n
        now = self._clock()
        if now >= self._next:
            self._next = now + self._period_s
            self._write(now)

    def finish(self) -> None:
        """Write the last update (what was done, however it ended), if anything was done: a
        source that failed at once leaves its one error line alone."""
        if self.done:
            self._write(self._clock())

    def _write(self, now: float) -> None:
        line = progress_line(self._label, self.done, self._total, now - self._start, self._unit)
        self._stream.write(line + "\n")
        self._stream.flush()
