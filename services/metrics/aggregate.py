"""Turns the messages the metrics service hears into a MetricsSnapshot. Pure: no bus, no clock.

Latency stages, all in ms, measured from the camera's capture stamp (``header.stamp_ns``):

    capture_to_detector    capture -> the detector took the frame (transport + queueing)
    preprocess / inference / postprocess    the detector's own stages
    capture_to_detections  capture -> detections published
    detections_to_command  detections published -> the first Twist reacting to them
    end_to_end             capture -> that first Twist (what the robot feels)

Cross-process figures compare wall clocks, so across hosts they need synchronised clocks (PTP
or chrony); on one host they are exact.

Besides the snapshot (``common.messages.MetricsSnapshot``), :meth:`Aggregator.extras` adds what
the message does not carry: the drop rate (frames the detector skipped because a newer one had
arrived, over the frames offered to it) and a per-second timeline (FPS over time) for plots.
"""

from __future__ import annotations

from collections import Counter, OrderedDict
from collections.abc import Callable

from common.contracts import MetricsAnswer, TimelineSeries
from common.messages import Detections, Header, MetricsSnapshot, ServiceCounters, Twist
from services.metrics.window import Timeline, Window, percentiles

NS_PER_MS = 1e6
DETECTOR_STAGES = ("preprocess", "inference", "postprocess")
STAGES = (
    "capture_to_detector",
    *DETECTOR_STAGES,
    "capture_to_detections",
    "detections_to_command",
    "end_to_end",
)
MAX_CLASSES = 1000  # distinct class names counted by default (COCO has 80, LVIS 1203)
MAX_COUNTERS = 2000  # distinct "<service>.<counter>" names kept
_RECENT = 512  # capture stamps remembered to pair Twists with the detections they react to
#: Per-second timeline columns: detections messages, boxes, frames offered to the detector
#: (its frames_in counter) and frames it dropped.
TIMELINE_COLUMNS = ("frames", "detections", "offered", "dropped")
#: The timeline stops this far behind now: counters arrive about once a second (slower while
#: inference is slow), so the latest seconds may still be missing their share of them.
TIMELINE_SETTLE_S = 2.0
_DETECTOR_DELTAS = {"frames_in": "offered", "dropped": "dropped"}

#: Called with (stage, milliseconds) for every latency sample, e.g. to feed a histogram.
LatencyListener = Callable[[str, float], None]


class Aggregator:
    """Accumulates per-stage latencies, rates and counters over a sliding window."""

    def __init__(
        self,
        window_s: float,
        history_s: float = 600.0,
        on_latency: LatencyListener | None = None,
        max_counters_per_service: int = MAX_COUNTERS,
        max_classes: int = MAX_CLASSES,
    ) -> None:
        self.window_s = window_s
        self.max_counters_per_service = max_counters_per_service
        self.max_classes = max_classes
        self._names: Counter[str] = Counter()  # service -> its counter names kept
        self._lat = {stage: Window(window_s) for stage in STAGES}
        self._frames = Window(window_s)  # one sample per Detections message: value = n boxes
        self._timeline = Timeline(history_s)
        self._on_latency = on_latency
        self._classes: Counter[str] = Counter()
        self._published: OrderedDict[int, int] = OrderedDict()  # capture stamp -> published_ns
        # The command can reach us before the detections it reacts to (they travel different
        # paths): capture stamp -> the first such command's stamp, paired when they arrive.
        self._early: OrderedDict[int, int] = OrderedDict()
        self._counters: dict[str, int] = {}
        self.frames_total = 0
        self.detections_total = 0
        self._detector_counters_at: float | None = None  # when its counters last came
        self._detector_counters_since: float | None = None  # ... and first came
        self.model = ""  # as the latest Detections named them
        self.backend = ""

    def _record(self, stage: str, now: float, ms: float) -> None:
        self._lat[stage].add(now, ms)
        if self._on_latency is not None:
            self._on_latency(stage, ms)

    def on_detections(self, msg: Detections, now: float) -> None:
        stamp = msg.header.stamp_ns
        self.frames_total += 1
        self.detections_total += len(msg)
        self.model, self.backend = msg.model, msg.backend
        self._frames.add(now, float(len(msg)))
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
            self.count("class_names_refused", refused)
        for stage in DETECTOR_STAGES:
            if stage in msg.timing_ms:
                self._record(stage, now, msg.timing_ms[stage])
        if msg.received_ns:
            self._record("capture_to_detector", now, (msg.received_ns - stamp) / NS_PER_MS)
        if msg.published_ns:
            self._record("capture_to_detections", now, (msg.published_ns - stamp) / NS_PER_MS)
            early = self._early.pop(stamp, None)
            if early is not None:
                self._record_reaction(now, stamp, msg.published_ns, early)
                return
            self._published[stamp] = msg.published_ns
            while len(self._published) > _RECENT:
                self._published.popitem(last=False)

    def on_twist(self, msg: Twist, now: float) -> None:
        """Score the first command that reacts to each frame; later repeats are ignored."""
        if msg.input_stamp_ns <= 0:
            return  # a stop that reacts to no frame
        published = self._published.pop(msg.input_stamp_ns, None)
        if published is None:
            self._early.setdefault(msg.input_stamp_ns, msg.header.stamp_ns)
            while len(self._early) > _RECENT:
                self._early.popitem(last=False)
            return
        self._record_reaction(now, msg.input_stamp_ns, published, msg.header.stamp_ns)

    def _record_reaction(self, now: float, captured: int, published: int, commanded: int) -> None:
        self._record("detections_to_command", now, (commanded - published) / NS_PER_MS)
        self._record("end_to_end", now, (commanded - captured) / NS_PER_MS)

    def on_counters(self, msg: ServiceCounters, now: float) -> None:
        """Keep each service's totals; put the detector's new offered/dropped frames on the
        timeline. A counter that went down means the service restarted and counts from zero."""
        deltas: dict[str, float] = {}
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
            column = _DETECTOR_DELTAS.get(name) if msg.service == "detector" else None
            if column is not None and previous is not None:
                deltas[column] = float(value - previous if value >= previous else value)
        if msg.service == "detector":
            if self._detector_counters_since is None:
                self._detector_counters_since = now  # a baseline: the drops before are unknown
            since, self._detector_counters_at = self._detector_counters_at, now
            if deltas and since is not None:
                self._timeline.spread(since, now, **deltas)

    def count(self, name: str, n: int = 1) -> None:
        """Count something the metrics service itself saw (e.g. its own bad input)."""
        key = f"metrics.{name}"
        self._counters[key] = self._counters.get(key, 0) + n

    def snapshot(self, header: Header, now: float) -> MetricsSnapshot:
        boxes = self._frames.values(now)
        return MetricsSnapshot(
            header=header,
            window_s=self.window_s,
            fps=self._frames.rate(now),
            frames=self.frames_total,
            detections=self.detections_total,
            detections_per_frame=float(boxes.mean()) if boxes.size else 0.0,
            dropped_frames=self._counters.get("detector.dropped", 0),
            latency_ms={stage: percentiles(w.values(now)) for stage, w in self._lat.items()},
            counters=dict(sorted(self._counters.items())),
            class_counts=dict(self._classes.most_common()),
        )

    def answer(self, header: Header, now: float, clock_to_unix: float = 0.0) -> MetricsAnswer:
        """The metrics query's JSON: the snapshot, drop rates and the per-second timeline.

        ``drop_rate`` covers the window (dropped / offered frames, 0 when none were offered);
        ``drop_rate_total`` the detector's counters since it started. The timeline's ``t`` is
        the caller's clock plus ``clock_to_unix`` (pass ``common.clock.mono_to_unix_s()`` for
        Unix seconds), from the detector's first counters (before them, offered and dropped
        frames are unknown) to :data:`TIMELINE_SETTLE_S` ago; ``fps`` and ``offered_fps`` are
        per second, ``dropped`` a count per period.
        """
        recent = self._timeline.totals(now, self.window_s)
        offered_total = self._counters.get("detector.frames_in", 0)
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
            drop_rate=_ratio(recent.get("dropped", 0.0), recent.get("offered", 0.0)),
            drop_rate_total=_ratio(self._counters.get("detector.dropped", 0), offered_total),
            frames_offered=offered_total,
            timeline=TimelineSeries(
                period_s=period,
                t=[t + clock_to_unix for t in series["t"]],
                fps=[f / period for f in frames],
                offered_fps=[f / period for f in series["offered"]],
                dropped=series["dropped"],
                detections_per_frame=[_ratio(b, f) for b, f in zip(boxes, frames, strict=True)],
            ),
        )

    def latency_samples(self, now: float) -> dict[str, list[float]]:
        """Every latency sample still in the window, per stage, in arrival order (ms)."""
        return {stage: w.values(now).tolist() for stage, w in self._lat.items()}


def _ratio(part: float, whole: float) -> float:
    return float(part) / float(whole) if whole > 0 else 0.0


def report_line(snap: MetricsSnapshot) -> str:
    """One human line: what a robot operator glances at."""
    lat = snap.latency_ms
    bad = sum(v for k, v in snap.counters.items() if k.endswith(".bad_input"))
    return (
        f"fps {snap.fps:.1f} | det/frame {snap.detections_per_frame:.2f} | "
        f"inference p50 {lat['inference']['p50']:.0f} ms | "
        f"capture->detections p50 {lat['capture_to_detections']['p50']:.0f} ms "
        f"p95 {lat['capture_to_detections']['p95']:.0f} ms | "
        f"end-to-end p50 {lat['end_to_end']['p50']:.0f} ms | "
        f"dropped {snap.dropped_frames} | bad input {bad}"
    )
