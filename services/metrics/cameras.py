"""What the services count for each camera, and the mean batch of the worker serving it. Pure:
no bus, no clock.

A service that serves several cameras keeps its totals under plain counter names and each
camera's under ``<name>.<camera>`` (common/counters.py::per_camera). The names read here:

    frames_in.<cam>       frames offered to the detector    -> frames_offered; names the worker
    dropped.<cam>         frames it skipped for a newer one -> dropped_frames, drop rates
    batches, batched_frames (the worker's plain names)     -> batch_mean of each camera it serves
    depth_in.<cam>, depth_unpaired.<cam> (its worker's)    -> depth_frames, depth_unpaired

Every other ``<name>.<cam>`` of any service (``detections_out.rear``, the controller's
``detections_in.rear``, the simulator's ``frames_out.rear`` ...) is shown under that camera as
``<service>.<name>``. The worker serving a camera (``served_by``) is the detector worker
whose latest ``serving.<cam>`` is 1 (a pool's workers hand cameras over: services/detector/
pool.py); from a worker that does not count ``serving``, the service counting
``frames_in.<cam>``.
"""

from __future__ import annotations

from collections import deque

from common.contracts import CameraMetrics
from services.detector import contract as detector
from services.metrics import contract
from services.metrics.figures import Figures
from services.metrics.window import Timeline

#: Counter name -> drop timeline column: frames offered to the worker, and dropped by it.
DROP_COLUMNS = {detector.FRAMES_IN: "offered", detector.DROPPED: "dropped"}
WORKER_COUNTER = detector.FRAMES_IN  # the service counting this for a camera serves it ...
SERVING_COUNTER = detector.SERVING  # ... unless a worker says so with this one (1: it serves it)
BATCH_COUNTERS = (detector.BATCHES, detector.BATCHED_FRAMES)


def ratio(part: float, whole: float) -> float:
    return float(part) / float(whole) if whole > 0 else 0.0


class CameraCounters:
    """One camera's counters, as every service reports them, and its drops over the window."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self.counters: dict[str, int] = {}  # "<service>.<name>" -> count, for this camera
        self.served_by = ""
        self._pool = False  # a worker counts SERVING_COUNTER: it, not WORKER_COUNTER, decides
        self._drops = Timeline(window_s + 2.0)  # the window and the period still filling
        self._pending: dict[str, float] = {}  # drop columns counted in the current message

    def count(self, service: str, name: str, value: int, delta: float | None) -> None:
        """``service``'s counter ``name`` for this camera is ``value``, up ``delta`` since its
        last report (None on the first)."""
        self.counters[f"{service}.{name}"] = value
        if name == SERVING_COUNTER:
            self._pool = True
            if value > 0:
                self.served_by = service
            elif self.served_by == service:
                self.served_by = ""  # it handed the camera on; the new worker says so next
        elif name == WORKER_COUNTER and not self._pool:
            self.served_by = service
        column = DROP_COLUMNS.get(name)
        if column is not None and delta is not None and service == self.served_by:
            self._pending[column] = self._pending.get(column, 0.0) + delta

    def settle(self, since: float | None, now: float) -> None:
        """End of one counters message: spread its deltas over the time since the previous."""
        if self._pending and since is not None:
            self._drops.spread(since, now, **self._pending)
        self._pending = {}

    def dropped(self) -> int:
        return self.counters.get(f"{self.served_by}.dropped", 0) if self.served_by else 0

    def offered(self) -> int:
        return self.worker_count(WORKER_COUNTER)

    def worker_count(self, name: str) -> int:
        """The serving worker's counter ``name`` for this camera (0 if none serves it)."""
        return self.counters.get(f"{self.served_by}.{name}", 0) if self.served_by else 0

    def drop_rate(self, now: float) -> float:
        recent = self._drops.totals(now, self.window_s)
        return ratio(recent.get("dropped", 0.0), recent.get("offered", 0.0))

    def figures(self, frames: Figures, now: float, batch_mean: float) -> CameraMetrics:
        """The camera's entry in the answer's ``cameras``."""
        return CameraMetrics(
            fps=frames.fps(now),
            frames=frames.frames_total,
            detections=frames.detections_total,
            detections_per_frame=frames.detections_per_frame(now),
            latency_ms=frames.latency_ms(now),
            dropped_frames=self.dropped(),
            frames_offered=self.offered(),
            drop_rate=self.drop_rate(now),
            drop_rate_total=ratio(self.dropped(), self.offered()),
            served_by=self.served_by,
            batch_mean=batch_mean,
            counters=dict(sorted(self.counters.items())),
            depth_frames=self.worker_count(contract.DEPTH_IN),
            depth_unpaired=self.worker_count(contract.DEPTH_UNPAIRED),
        )


class BatchSizes:
    """Each worker's mean batch over the window, from its ``batches`` and ``batched_frames``
    counters (frames per inference run; 0 when it ran none in the window)."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self._seen: dict[str, deque[tuple[float, int, int]]] = {}  # service -> (t, runs, frames)

    def on_counters(self, service: str, counters: dict[str, int], now: float) -> None:
        if not all(name in counters for name in BATCH_COUNTERS):
            return
        runs, frames = (counters[name] for name in BATCH_COUNTERS)
        seen = self._seen.setdefault(service, deque())
        if seen and (runs < seen[-1][1] or frames < seen[-1][2]):
            seen.clear()  # the worker restarted and counts from zero
        seen.append((now, runs, frames))
        while len(seen) > 1 and seen[1][0] <= now - self.window_s:
            seen.popleft()  # keep one report at or before the window's start, as a baseline

    def mean(self, service: str) -> float:
        seen = self._seen.get(service)
        if not seen:
            return 0.0
        (_, runs0, frames0), (_, runs1, frames1) = seen[0], seen[-1]
        if len(seen) == 1:
            return ratio(frames1, runs1)  # one report: the worker's mean since it started
        return ratio(frames1 - frames0, runs1 - runs0)
