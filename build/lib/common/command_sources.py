"""Who is commanding the robot? Counts the publishers heard on the command key. Pure.

The robot side (the simulator, a ROS 2 bridge) should hear exactly one controller. A second
publisher (a forgotten stack, a teleop node, a rogue) interleaves its commands with ours; that
is reported, never silently obeyed.
"""

from __future__ import annotations

MAX_SOURCES = 256  # a flood of made-up ids cannot grow the table beyond this


class CommandSources:
    """The publishers heard within the last ``window_s`` seconds."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self._last_heard: dict[str, float] = {}

    def heard(self, source: str, now: float) -> tuple[int, bool]:
        """Note a command from ``source`` at ``now`` (monotonic seconds); returns how many
        sources are active now, this one included, and whether it is new."""
        self._last_heard = {s: t for s, t in self._last_heard.items() if now - t <= self.window_s}
        new = source not in self._last_heard
        if new and len(self._last_heard) >= MAX_SOURCES:
            oldest = min(self._last_heard, key=self._last_heard.__getitem__)
            del self._last_heard[oldest]
        self._last_heard[source] = now
        return len(self._last_heard), new

    def active(self) -> list[str]:
        return sorted(self._last_heard)
