"""A live camera that stops giving frames is reopened (services/camera/reopen.py), driven with
fake sources and a fake clock whose stop event advances time instead of sleeping."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from unittest.mock import MagicMock

import numpy as np
import pytest

from common.errors import ConfigError
from common.images import Image
from services.camera.contract import CameraSettings
from services.camera.depth import DepthImage
from services.camera.reopen import HEARTBEAT_S, ReopenHooks, ReopeningSource
from services.camera.service import _reopening
from services.camera.sources import FrameSource, depth_capable

DEVICE = "camera device 9"


def _image(value: int) -> Image:
    return np.full((2, 2, 3), value, np.uint8)


class FakeSource:
    """Gives its items in order (an Exception is raised), then None: a device that stopped."""

    def __init__(self, *items: Image | Exception, live: bool = True) -> None:
        self._items = list(items)
        self.description = DEVICE
        self.live = live
        self.closed = False

    def read(self) -> Image | None:
        if not self._items:
            return None
        item = self._items.pop(0)
        if isinstance(item, Exception):
            raise item
        return item

    def close(self) -> None:
        self.closed = True


class FakeTime:
    """A clock and a stop event: ``wait`` advances the clock by its timeout (stop is set once
    the clock reaches ``stop_at``)."""

    def __init__(self, stop_at: float = float("inf")) -> None:
        self.now = 0.0
        self.stop_at = stop_at

    def clock(self) -> float:
        return self.now

    def is_set(self) -> bool:
        return self.now >= self.stop_at

    def wait(self, timeout: float | None = None) -> bool:
        assert timeout is not None and 0 < timeout <= HEARTBEAT_S
        self.now = min(self.now + timeout, self.stop_at)
        return self.is_set()


class HookCalls:
    """The hooks, recording each call and the fake time it came at."""

    def __init__(self, time_: FakeTime) -> None:
        self.time = time_
        self.lost: list[str] = []
        self.failed: list[str] = []
        self.reopened: list[str] = []
        self.beats: list[float] = []
        self.hooks = ReopenHooks(
            lost=self.lost.append,
            failed=self.failed.append,
            reopened=self.reopened.append,
            heartbeat=lambda: self.beats.append(time_.now),
        )


def _factory(
    time_: FakeTime, *results: FrameSource | Exception
) -> tuple[Callable[[], FrameSource], list[float]]:
    """A factory returning (or raising) ``results`` in order; also the times it was called."""
    calls: list[float] = []
    queue = list(results)

    def factory() -> FrameSource:
        calls.append(time_.now)
        result = queue.pop(0)
        if isinstance(result, Exception):
            raise result
        return result

    return factory, calls


def _values(source: FrameSource, n: int) -> list[int | None]:
    out: list[int | None] = []
    for _ in range(n):
        image = source.read()
        out.append(None if image is None else int(image[0, 0, 0]))
    return out


def test_a_live_source_that_ends_is_reopened_and_frames_continue() -> None:
    t = FakeTime()
    rec = HookCalls(t)
    first, second = FakeSource(_image(1)), FakeSource(_image(2), _image(3))
    factory, calls = _factory(t, second)
    src = ReopeningSource(first, factory, period_s=1.0, stop=t, hooks=rec.hooks, clock=t.clock)
    assert _values(src, 3) == [1, 2, 3]
    assert first.closed and not second.closed and calls == [1.0]
    assert rec.lost == [f"{DEVICE} stopped giving frames (unplugged?); reopening every 1 s"]
    assert rec.reopened == [f"{DEVICE} reopened after 1.0 s"] and rec.failed == []
    src.close()
    assert second.closed


@pytest.mark.parametrize("period", [1.0, 60.0])
def test_failed_attempts_are_retried_at_the_period_with_heartbeats(period: float) -> None:
    t = FakeTime()
    rec = HookCalls(t)
    missing = ConfigError(f"{DEVICE}: no such device")
    factory, calls = _factory(t, missing, missing, FakeSource(_image(7)))
    src = ReopeningSource(
        FakeSource(_image(1)), factory, period_s=period, stop=t, hooks=rec.hooks, clock=t.clock
    )
    assert _values(src, 2) == [1, 7]
    assert calls == [period, 2 * period, 3 * period]
    assert len(rec.failed) == 2 and all(line.startswith(str(missing)) for line in rec.failed)
    assert len(rec.lost) == 1 and len(rec.reopened) == 1
    # Every attempt is followed by a heartbeat, and the wait never goes longer without one
    # (the supervisor's watchdog would take the camera for hung).
    assert set(calls) <= set(rec.beats)
    gaps = np.diff([0.0, *rec.beats])
    assert gaps.max() <= HEARTBEAT_S


def test_stop_during_the_wait_returns_promptly() -> None:
    stop = threading.Event()
    rec = HookCalls(FakeTime())
    factory, calls = _factory(FakeTime(), *[ConfigError("gone")] * 100)
    first = FakeSource(_image(1))
    src = ReopeningSource(first, factory, period_s=30.0, stop=stop, hooks=rec.hooks)
    assert src.read() is not None
    timer = threading.Timer(0.05, stop.set)
    timer.start()
    started = time.monotonic()
    assert src.read() is None
    assert time.monotonic() - started < 5.0  # far below the 30 s period
    timer.join()
    assert first.closed and calls == [] and rec.reopened == []


def test_stop_between_attempts_ends_the_wait() -> None:
    t = FakeTime(stop_at=2.5)
    rec = HookCalls(t)
    factory, calls = _factory(t, ConfigError("gone"), ConfigError("gone"))
    src = ReopeningSource(
        FakeSource(_image(1)), factory, period_s=1.0, stop=t, hooks=rec.hooks, clock=t.clock
    )
    assert _values(src, 2) == [1, None]
    assert calls == [1.0, 2.0] and t.now == 2.5 and rec.reopened == []


def test_a_reopened_source_without_a_first_frame_is_still_lost() -> None:
    t = FakeTime()
    rec = HookCalls(t)
    blank = FakeSource(ConfigError(f"{DEVICE}: not one frame could be read"))
    empty = FakeSource()  # opens, then read() gives None at once
    factory, calls = _factory(t, blank, empty, FakeSource(_image(5)))
    src = ReopeningSource(
        FakeSource(_image(1)), factory, period_s=0.5, stop=t, hooks=rec.hooks, clock=t.clock
    )
    assert _values(src, 2) == [1, 5]
    assert calls == [0.5, 1.0, 1.5] and blank.closed and empty.closed
    assert len(rec.failed) == 2 and "not one frame could be read" in rec.failed[0]
    assert rec.reopened == [f"{DEVICE} reopened after 1.5 s"]


def test_a_config_error_after_frames_is_a_loss_too() -> None:
    t = FakeTime()
    rec = HookCalls(t)
    failing = FakeSource(_image(1), ConfigError(f"{DEVICE}: not one frame could be read"))
    factory, calls = _factory(t, FakeSource(_image(4)))
    src = ReopeningSource(failing, factory, period_s=1.0, stop=t, hooks=rec.hooks, clock=t.clock)
    assert _values(src, 2) == [1, 4]
    assert failing.closed and calls == [1.0] and len(rec.lost) == len(rec.reopened) == 1


def test_a_device_that_never_gave_a_frame_fails_as_at_start_up() -> None:
    t = FakeTime()
    rec = HookCalls(t)
    factory, calls = _factory(t)
    src = ReopeningSource(
        FakeSource(ConfigError(f"{DEVICE}: not one frame could be read")),
        factory,
        period_s=1.0,
        stop=t,
        hooks=rec.hooks,
        clock=t.clock,
    )
    with pytest.raises(ConfigError, match="not one frame"):
        src.read()
    assert calls == [] and rec.lost == []


def test_a_non_live_source_that_ends_still_ends() -> None:
    node = MagicMock()
    video = FakeSource(_image(1), live=False)
    source = _reopening(video, CameraSettings(), node, threading.Event())
    assert source is video
    assert _values(source, 2) == [1, None]
    node.counters.add.assert_not_called()


def test_a_live_source_is_wrapped_and_counted() -> None:
    node = MagicMock()
    device = FakeSource(_image(1))
    stop = threading.Event()
    source = _reopening(
        device, CameraSettings(source="device:/dev/nonexistent9", reopen_period_s=0.05), node, stop
    )
    assert isinstance(source, ReopeningSource) and source.live
    assert source.read() is not None
    # The device is gone: each reopen fails (no such device) until stop is set.
    node.reject.side_effect = lambda counter, line: stop.set()
    assert source.read() is None
    node.counters.add.assert_called_once_with("source_lost")
    counter, line = node.reject.call_args.args
    assert counter == "source_reopen_failed" and "no such device" in line


def test_the_reopen_period_is_a_bounded_setting() -> None:
    assert CameraSettings().reopen_period_s == 1.0
    with pytest.raises(ConfigError, match="reopen_period_s"):
        CameraSettings(reopen_period_s=0.0)


class FakeDepthSource(FakeSource):
    """A live RGB-D camera: each frame's depth is a 1x1 image of the frame's value in mm."""

    has_depth = True

    def __init__(self, *items: Image | Exception) -> None:
        super().__init__(*items)
        self._last: Image | None = None

    def read(self) -> Image | None:
        self._last = super().read()
        return self._last

    def depth(self) -> DepthImage | None:
        if self._last is None:
            return None
        value = np.full((1, 1), int(self._last[0, 0, 0]), np.uint16)
        return DepthImage(data=value, scale_m=0.001, fx=1.0, fy=1.0, cx=0.5, cy=0.5)


def test_a_reopened_depth_camera_gives_the_depth_of_its_new_frames() -> None:
    t = FakeTime()
    rec = HookCalls(t)
    first, second = FakeDepthSource(_image(1)), FakeDepthSource(_image(2))
    factory, _ = _factory(t, second)
    src = ReopeningSource(first, factory, period_s=1.0, stop=t, hooks=rec.hooks, clock=t.clock)
    assert src.has_depth and depth_capable(src) is src
    depths = []
    for _ in range(2):
        assert src.read() is not None
        depth = src.depth()
        assert depth is not None
        depths.append(int(depth.data[0, 0]))
    assert depths == [1, 2] and rec.reopened
    plain = ReopeningSource(
        FakeSource(_image(1)), factory, period_s=1.0, stop=t, hooks=rec.hooks, clock=t.clock
    )
    assert not plain.has_depth and depth_capable(plain) is None and plain.depth() is None
