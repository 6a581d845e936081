"""Turns the messages the metrics service hears into a MetricsSnapshot. Pure: no bus, no clock.

Latency stages, all in ms, measured from the camera's capture stamp (``header.stamp_ns``):

    capture_to_detector    capture -> the detector took the frame (transport + queueing)
    preprocess / inference / postprocess    the detector's own stages
    capture_to_detections  capture -> detections published
    detections_to_command  detections published -> the first Twist reacting to them
    end_to_end             capture -> that first Twist (what the robot feels)

Cross-process figures compare wall clocks, so across hosts they need synchronised clocks (PTP
or chrony); on one host they are exact.
"""

from __future__ import annotations

from collections import Counter, OrderedDict

from common.messages import Detections, Header, MetricsSnapshot, ServiceCounters, Twist
from services.metrics.window import Window, percentiles

NS_PER_MS = 1e6
DETECTOR_STAGES = ("preprocess", "inference", "postprocess")
STAGES = (
    "capture_to_detector",
    *DETECTOR_STAGES,
    "capture_to_detections",
    "detections_to_command",
    "end_to_end",
)
_RECENT = 512  # capture stamps remembered to pair Twists with the detections they react to


class Aggregator:
    """Accumulates per-stage latencies, rates and counters over a sliding window."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self._lat = {stage: Window(window_s) for stage in STAGES}
        self._frames = Window(window_s)  # one sample per Detections message: value = n boxes
        self._classes: Counter[str] = Counter()
        self._published: OrderedDict[int, int] = OrderedDict()  # capture stamp -> published_ns
        self._counters: dict[str, int] = {}
        self.frames_total = 0
        self.detections_total = 0

    def on_detections(self, msg: Detections, now: float) -> None:
        stamp = msg.header.stamp_ns
        self.frames_total += 1
        self.detections_total += len(msg)
        self._frames.add(now, float(len(msg)))
        self._classes.update(msg.class_names)
        for stage in DETECTOR_STAGES:
            if stage in msg.timing_ms:
                self._lat[stage].add(now, msg.timing_ms[stage])
        if msg.received_ns:
            self._lat["capture_to_detector"].add(now, (msg.received_ns - stamp) / NS_PER_MS)
        if msg.published_ns:
            self._lat["capture_to_detections"].add(now, (msg.published_ns - stamp) / NS_PER_MS)
            self._published[stamp] = msg.published_ns
            while len(self._published) > _RECENT:
                self._published.popitem(last=False)

    def on_twist(self, msg: Twist, now: float) -> None:
        """Score the first command that reacts to each frame; later repeats are ignored."""
        published = self._published.pop(msg.input_stamp_ns, None)
        if published is None:
            return
        self._lat["detections_to_command"].add(now, (msg.header.stamp_ns - published) / NS_PER_MS)
        self._lat["end_to_end"].add(now, (msg.header.stamp_ns - msg.input_stamp_ns) / NS_PER_MS)

    def on_counters(self, msg: ServiceCounters) -> None:
        for name, value in msg.counters.items():
            self._counters[f"{msg.service}.{name}"] = value

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
