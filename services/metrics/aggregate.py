"""Turns the messages the metrics service hears into a MetricsSnapshot and the query's answer.
Pure: no bus, no clock.

The latency stages are in services/metrics/figures.py. The top-level figures are every camera's
together; ``cameras`` in the answer has each camera's (services/metrics/cameras.py says which
counters it reads). A command is attributed to the camera whose frame it reacts to by its
capture stamp (services/metrics/reactions.py).

Cross-process figures compare wall clocks, so across hosts they need synchronised clocks (PTP
or chrony); on one host they are exact.

Besides the snapshot (``common.messages.MetricsSnapshot``), :meth:`Aggregator.answer` adds what
the message does not carry: the drop rate (frames the detector skipped because a newer one had
arrived, over the frames offered to it), a per-second timeline (FPS over time) for plots, the
depth images the detector took and its colour frames with none in time, and each camera's
figures.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable

from common.contracts import CameraMetrics, MetricsAnswer, TimelineSeries
from common.messages import Detections, Header, MetricsSnapshot, ServiceCounters, Twist
from common.pool_audit import lines
from common.settings import MAX_CAMERAS, service_package
from services.detector import contract as detector
from services.metrics import contract
from services.metrics.cameras import BatchSizes, CameraCounters, ratio
from services.metrics.figures import DETECTOR_STAGES, STAGES, Figures, LatencyListener
from services.metrics.pool import Duplicates, LivePool, workers
from services.metrics.reactions import Reaction, Reactions
from services.metrics.window import Timeline

__all__ = ["DETECTOR_STAGES", "STAGES", "Aggregator", "LatencyListener", "report_line"]

MAX_CLASSES = 1000  # distinct class names counted by default (COCO has 80, LVIS 1203)
MAX_COUNTERS = 2000  # distinct "<service>.<counter>" names kept
_RECENT = 512  # capture stamps remembered per camera, to pair Twists with their detections
#: Per-second timeline columns: detections messages, boxes, frames offered to the detector
#: (its frames_in counter) and frames it dropped.
TIMELINE_COLUMNS = ("frames", "detections", "offered", "dropped")
#: The timeline stops this far behind now: counters arrive about once a second (slower while
#: inference is slow), so the latest seconds may still be missing their share of them.
TIMELINE_SETTLE_S = 2.0
_DETECTOR_DELTAS = {detector.FRAMES_IN: "offered", detector.DROPPED: "dropped"}


class Aggregator:
    """Accumulates per-stage latencies, rates and counters over a sliding window, for every
    camera together and for each (``cameras`` are shown from the start, even before their
    first detections; another camera is added when its detections come, up to
    ``max_cameras``)."""

    def __init__(
        self,
        window_s: float,
        history_s: float = 600.0,
        on_latency: LatencyListener | None = None,
        max_counters_per_service: int = MAX_COUNTERS,
        max_classes: int = MAX_CLASSES,
        cameras: Iterable[str] = (),
        max_cameras: int = MAX_CAMERAS,
        pool: LivePool | None = None,
    ) -> None:
        self.window_s = window_s
        self.max_counters_per_service = max_counters_per_service
        self.max_classes = max_classes
        self.max_cameras = max_cameras
        self._on_latency = on_latency
        self._names: Counter[str] = Counter()  # service -> its counter names kept
        self._all = Figures(window_s, "", on_latency)
        self._figures: dict[str, Figures] = {}  # camera -> its own
        self._camera_counters: dict[str, CameraCounters] = {}
        self._reactions = Reactions(_RECENT)  # per camera: grows with them
        for camera in cameras:
            self._camera(camera)
        self._batches = BatchSizes(window_s)
        self._timeline = Timeline(history_s)
        self._classes: Counter[str] = Counter()
        self._counters: dict[str, int] = {}
        self._reported_at: dict[str, float] = {}  # service -> when its counters last came
        self._detector_counters_since: float | None = None  # ... and the detector's first came
        self._duplicates = Duplicates()  # frames detected twice (a pool's hand-over)
        #: The pool's tokens (who serves which camera, what is wrong), when they are heard.
        self.pool = pool
        self.model = ""  # as the latest Detections named them
        self.backend = ""

    @property
    def frames_total(self) -> int:
        return self._all.frames_total

    @property
    def detections_total(self) -> int:
        return self._all.detections_total

    def add_camera(self, camera: str) -> None:
        """Show ``camera``'s figures from now on (if there is room), before its detections."""
        self._camera(camera)

    def _camera(self, camera: str) -> Figures | None:
        """``camera``'s figures, added if there is room."""
        figures = self._figures.get(camera)
        if figures is None and len(self._figures) < self.max_cameras:
            figures = self._figures[camera] = Figures(self.window_s, camera, self._on_latency)
            self._camera_counters[camera] = CameraCounters(self.window_s)
            self._reactions.keep = _RECENT * len(self._figures)
        return figures

    def on_detections(self, msg: Detections, now: float, *, camera: str) -> None:
        """``camera``'s detections (the camera its key names). A frame detected twice (two
        workers during a hand-over) is counted as ``duplicate_detections`` and shown as
        published: the controller heard both."""
        self.model, self.backend = msg.model, msg.backend
        self._all.on_detections(msg, now)
        figures = self._camera(camera)
        if figures is None:
            self.count(contract.CAMERAS_REFUSED)  # over max_cameras: in the totals only
        else:
            # Only for the cameras kept (at most max_cameras): made-up camera names on the
            # detections keys must not grow the memory of frames seen.
            if self._duplicates.seen(camera, msg.header):
                self.count(contract.DUPLICATE_DETECTIONS)
            figures.on_detections(msg, now)
        self._timeline.add(now, frames=1.0, detections=float(len(msg)))
        # Bounded: garbage that decodes can still name thousands of made-up classes (each
        # name is bounded in length where it enters: common.messages.MAX_NAME_CHARS).
        refused = 0
        for name in msg.class_names:
            if name in self._classes or len(self._classes) < self.max_classes:
                self._classes[name] += 1
            else:
                refused += 1
        if refused:
            self.count(contract.CLASS_NAMES_REFUSED, refused)
        if msg.published_ns and figures is not None:
            stamp = msg.header.stamp_ns
            self._score(now, self._reactions.on_detections(camera, stamp, msg.published_ns))

    def on_twist(self, msg: Twist, now: float) -> None:
        """Score the first command that reacts to each frame; later repeats are ignored."""
        if msg.input_stamp_ns <= 0:
            return  # a stop that reacts to no frame
        self._score(now, self._reactions.on_command(msg.input_stamp_ns, msg.header.stamp_ns))

    def _score(self, now: float, reactions: list[Reaction]) -> None:
        for r in reactions:
            self._figures[r.camera].on_reaction(now, r.captured, r.published, r.commanded)
            if r.first:
                self._all.on_reaction(now, r.captured, r.published, r.commanded)

    def on_counters(self, msg: ServiceCounters, now: float) -> None:
        """Keep each service's totals; put the detector's new offered/dropped frames on the
        timeline; give each camera its ``<name>.<camera>`` counters. A counter that went down
        means the service restarted and counts from zero."""
        deltas: dict[str, float] = {}
        touched: set[str] = set()
        for name, value in msg.counters.items():
            key = f"{msg.service}.{name}"
            previous = self._counters.get(key)
            if previous is None:
                if (
                    len(self._counters) >= MAX_COUNTERS
                    or self._names[msg.service] >= self.max_counters_per_service
                ):
                    continue  # bounded, like the class counts
                self._names[msg.service] += 1
            self._counters[key] = value
            delta = None
            if previous is not None:
                delta = float(value - previous if value >= previous else value)
            is_detector = service_package(msg.service) == "detector"  # any worker of the pool
            column = _DETECTOR_DELTAS.get(name) if is_detector else None
            if column is not None and delta is not None:
                deltas[column] = delta
            base, _, camera = name.rpartition(".")
            counters = self._camera_counters.get(camera) if base else None
            if counters is not None:
                counters.count(msg.service, base, value, delta)
                touched.add(camera)
        since = self._reported_at.get(msg.service)
        if msg.service in self._names:  # a service with counters kept (bounded)
            self._reported_at[msg.service] = now
            self._batches.on_counters(msg.service, msg.counters, now)
        for camera in touched:
            self._camera_counters[camera].settle(since, now)
        if service_package(msg.service) == "detector":
            if self._detector_counters_since is None:
                self._detector_counters_since = now  # a baseline: the drops before are unknown
            if deltas and since is not None:
                self._timeline.spread(since, now, **deltas)

    def _detector_total(self, name: str) -> int:
        """Counter ``name`` summed over every detector worker (one unless a pool)."""
        return sum(v for key, v in self._counters.items() if _is_detector(key, name))

    def count(self, name: str, n: int = 1) -> None:
        """Count something the metrics service itself saw (e.g. its own bad input)."""
        key = f"metrics.{name}"
        self._counters[key] = self._counters.get(key, 0) + n

    def snapshot(self, header: Header, now: float) -> MetricsSnapshot:
        return MetricsSnapshot(
            header=header,
            window_s=self.window_s,
            fps=self._all.fps(now),
            frames=self._all.frames_total,
            detections=self._all.detections_total,
            detections_per_frame=self._all.detections_per_frame(now),
            dropped_frames=self._detector_total(detector.DROPPED),
            latency_ms=self._all.latency_ms(now),
            counters=dict(sorted(self._counters.items())),
            class_counts=dict(self._classes.most_common()),
        )

    def cameras(self, now: float) -> dict[str, CameraMetrics]:
        """Each camera's figures, in the order the cameras were named."""
        out = {}
        for camera, figures in self._figures.items():
            counters = self._camera_counters[camera]
            batch_mean = self._batches.mean(counters.served_by) if counters.served_by else 0.0
            out[camera] = counters.figures(figures, now, batch_mean)
            if self.pool is not None and self.pool.heard:
                out[camera]["served_by"] = self.pool.served_by(camera)  # the live pool's word
            out[camera]["duplicate_detections"] = self._duplicates.per_camera.get(camera, 0)
        return out

    def answer(self, header: Header, now: float, clock_to_unix: float = 0.0) -> MetricsAnswer:
        """The metrics query's JSON: the snapshot, drop rates, the per-second timeline and
        each camera's figures.

        ``drop_rate`` covers the window (dropped / offered frames, 0 when none were offered);
        ``drop_rate_total`` the detector's counters since it started. The timeline's ``t`` is
        the caller's clock plus ``clock_to_unix`` (pass ``common.clock.mono_to_unix_s()`` for
        Unix seconds), from the detector's first counters (before them, offered and dropped
        frames are unknown) to :data:`TIMELINE_SETTLE_S` ago; ``fps`` and ``offered_fps`` are
        per second, ``dropped`` a count per period.
        """
        recent = self._timeline.totals(now, self.window_s)
        offered_total = self._detector_total(detector.FRAMES_IN)
        series = self._timeline.series(
            now - TIMELINE_SETTLE_S, TIMELINE_COLUMNS, since=self._detector_counters_since
        )
        period = self._timeline.period_s
        frames, boxes = series["frames"], series["detections"]
        snap = self.snapshot(header, now)
        return MetricsAnswer(
            stamp_ns=snap.header.stamp_ns,
            window_s=snap.window_s,
            fps=snap.fps,
            frames=snap.frames,
            detections=snap.detections,
            detections_per_frame=snap.detections_per_frame,
            dropped_frames=snap.dropped_frames,
            latency_ms=snap.latency_ms,
            counters=snap.counters,
            class_counts=snap.class_counts,
            drop_rate=ratio(recent.get("dropped", 0.0), recent.get("offered", 0.0)),
            drop_rate_total=ratio(self._detector_total(detector.DROPPED), offered_total),
            frames_offered=offered_total,
            timeline=TimelineSeries(
                period_s=period,
                t=[t + clock_to_unix for t in series["t"]],
                fps=[f / period for f in frames],
                offered_fps=[f / period for f in series["offered"]],
                dropped=series["dropped"],
                detections_per_frame=[ratio(b, f) for b, f in zip(boxes, frames, strict=True)],
            ),
            cameras=self.cameras(now),
            workers=workers(self._counters, self._figures, self._reported_at, now, self.pool),
            duplicate_detections=self._duplicates.total,
            pool_warnings=[] if self.pool is None else lines(self.pool.report.current, now),
            depth_frames=self._detector_total(contract.DEPTH_IN),
            depth_unpaired=self._detector_total(contract.DEPTH_UNPAIRED),
        )

    def latency_samples(self, now: float) -> dict[str, list[float]]:
        """Every latency sample still in the window, per stage, in arrival order (ms), of
        every camera together."""
        return self._all.latency_samples(now)


def _is_detector(key: str, name: str) -> bool:
    """Whether ``key`` (``<service>.<counter>``) is a detector worker's total ``name``."""
    service, _, counter = key.partition(".")
    return counter == name and service_package(service) == "detector"


def report_line(snap: MetricsSnapshot) -> str:
    """One human line: what a robot operator glances at."""
    lat = snap.latency_ms
    bad = sum(v for k, v in snap.counters.items() if k.endswith(".bad_input"))
    depth = ""
    if lat.get("depth", {}).get("count"):  # a depth camera's frames measured in the window
        unpaired = sum(
            v for k, v in snap.counters.items() if _is_detector(k, contract.DEPTH_UNPAIRED)
        )
        depth = f"depth p50 {lat['depth']['p50']:.1f} ms | depth unpaired {unpaired} | "
    return (
        f"fps {snap.fps:.1f} | det/frame {snap.detections_per_frame:.2f} | "
        f"inference p50 {lat['inference']['p50']:.0f} ms | "
        f"capture->detections p50 {lat['capture_to_detections']['p50']:.0f} ms "
        f"p95 {lat['capture_to_detections']['p95']:.0f} ms | "
        f"end-to-end p50 {lat['end_to_end']['p50']:.0f} ms | {depth}"
        f"dropped {snap.dropped_frames} | bad input {bad}"
    )
