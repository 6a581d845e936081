"""A live camera that stops giving frames is reopened, not abandoned. Pure: no bus, no OpenCV.

A USB camera that is unplugged or resets makes its capture return no frame (``read()`` gives
None). For a video file that is the end; for a device it is a glitch that the device recovers
from. :class:`ReopeningSource` wraps a live source: when it ends after it gave frames, the
source is closed and opened again through ``factory`` every ``period_s`` until a new one opens
*and* gives a frame (a device that opens but gives nothing, ConfigError "not one frame could be
read", is still lost), or until ``stop`` is set. The caller's hooks count and log; the wait
calls ``heartbeat`` at least every :data:`HEARTBEAT_S`, so that the service still publishes its
counters (the supervisor's watchdog takes them for the work loop's heartbeat).

A source that fails *before* its first frame is left alone: its ConfigError goes up as at
start-up (one line, exit 2), since only a device that worked is worth waiting for.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, cast

from common.clock import mono_s
from common.errors import ConfigError

if TYPE_CHECKING:
    from common.images import Image
    from services.camera.depth import DepthImage
    from services.camera.sources import FrameSource

#: The longest stretch the wait goes without calling ``heartbeat`` (half the nodes' counters
#: period, so that a long ``reopen_period_s`` never starves the watchdog).
HEARTBEAT_S = 0.5


class EventLike(Protocol):
    """What the wait needs of a ``threading.Event`` (common.lifecycle.StopEvent is one; a test
    passes a fake clock's)."""

    def is_set(self) -> bool: ...

    def wait(self, timeout: float | None = None) -> bool: ...


@dataclass(frozen=True, slots=True)
class ReopenHooks:
    """What the service does on each event (each gets the line to log, already written):
    ``lost`` once when the source stops, ``failed`` per failed attempt (the caller rate-limits
    its log), ``reopened`` once when frames come again; ``heartbeat`` during the wait."""

    lost: Callable[[str], None]
    failed: Callable[[str], None]
    reopened: Callable[[str], None]
    heartbeat: Callable[[], None]


class ReopeningSource:
    """A live :class:`FrameSource` that reopens itself through ``factory`` when it ends.

    ``read()`` returns None only when ``stop`` was set while the source was lost (or when the
    source ended before giving one frame, which a device reports as ConfigError instead).
    """

    live = True

    def __init__(
        self,
        source: FrameSource,
        factory: Callable[[], FrameSource],
        *,
        period_s: float,
        stop: EventLike,
        hooks: ReopenHooks,
        clock: Callable[[], float] = mono_s,
    ) -> None:
        if period_s <= 0:
            raise ValueError("period_s must be > 0")
        self._source: FrameSource | None = source
        self._factory = factory
        self._period_s = period_s
        self._stop = stop
        self._hooks = hooks
        self._clock = clock
        self._frames = 0  # given by this wrapper, over every source it held
        self.description = source.description
        #: A depth camera stays one when reopened: the depth of each frame, as its source's.
        self.has_depth = bool(getattr(source, "has_depth", False))

    def read(self) -> Image | None:
        image = self._read_current()
        if image is None and self._frames:
            image = self._reopen()
        if image is not None:
            self._frames += 1
        return image

    def depth(self) -> DepthImage | None:
        """The depth of the frame read last, from the source that gave it (None when lost)."""
        depth = getattr(self._source, "depth", None) if self.has_depth else None
        return cast("DepthImage | None", depth()) if depth is not None else None

    def _read_current(self) -> Image | None:
        if self._source is None:
            return None
        try:
            return self._source.read()
        except ConfigError:
            if not self._frames:
                raise  # nothing ever came: as at start-up, one line and exit 2
            return None

    def _reopen(self) -> Image | None:
        """Close the lost source; open it again every period until it gives a frame (that
        frame) or ``stop`` is set (None)."""
        if self._source is not None:
            self._source.close()
            self._source = None
        lost_at = self._clock()
        self._hooks.lost(
            f"{self.description} stopped giving frames (unplugged?); "
            f"reopening every {self._period_s:g} s"
        )
        while self._wait(self._period_s):
            source: FrameSource | None = None
            try:
                source = self._factory()
                image = source.read()
                if image is None:
                    raise ConfigError(f"{source.description}: no frame")
            except (ConfigError, OSError) as exc:
                if source is not None:
                    source.close()
                self._hooks.failed(
                    f"{exc}; lost for {self._clock() - lost_at:.0f} s, "
                    f"retrying every {self._period_s:g} s"
                )
                self._hooks.heartbeat()
                continue
            self._source = source
            self._hooks.reopened(
                f"{self.description} reopened after {self._clock() - lost_at:.1f} s"
            )
            self._hooks.heartbeat()
            return image
        return None

    def _wait(self, seconds: float) -> bool:
        """Wait ``seconds``, calling the heartbeat on the way; False as soon as stop is set."""
        deadline = self._clock() + seconds
        while (left := deadline - self._clock()) > 0:
            if self._stop.wait(min(left, HEARTBEAT_S)):
                return False
            self._hooks.heartbeat()
        return not self._stop.is_set()

    def close(self) -> None:
        if self._source is not None:
            self._source.close()
            self._source = None
