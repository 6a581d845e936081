"""The figures of one stream of detections over a sliding window: the whole stack's, and each
camera's. Pure: no bus, no clock.

Latency stages, all in ms, measured from the camera's capture stamp (``header.stamp_ns``):

    capture_to_detector    capture -> the detector took the frame (transport + queueing)
    preprocess / inference / postprocess    the detector's own stages
    depth                  the detector's depth stage: pairing and measuring the boxes (only
                           frames that had a depth image)
    capture_to_detections  capture -> detections published
    detections_to_command  detections published -> the first Twist reacting to them
    end_to_end             capture -> that first Twist (what the robot feels)
"""

from __future__ import annotations

from collections.abc import Callable

from common.contracts import LatencyStats
from common.messages import Detections
from services.metrics.window import Window, percentiles

NS_PER_MS = 1e6
DETECTOR_STAGES = ("preprocess", "inference", "postprocess", "depth")
STAGES = (
    "capture_to_detector",
    *DETECTOR_STAGES,
    "capture_to_detections",
    "detections_to_command",
    "end_to_end",
)

#: Called with (stage, milliseconds, camera) for every latency sample, e.g. to feed a
#: histogram; ``camera`` is "" for the stack's totals (each sample also comes once with its
#: camera's name).
LatencyListener = Callable[[str, float, str], None]


class Figures:
    """FPS, boxes per frame, totals and each stage's latency of ``camera``'s detections ("" for
    every camera's together)."""

    def __init__(
        self, window_s: float, camera: str = "", on_latency: LatencyListener | None = None
    ) -> None:
        self.camera = camera
        self._lat = {stage: Window(window_s) for stage in STAGES}
        self._frames = Window(window_s)  # one sample per Detections message: value = n boxes
        self._on_latency = on_latency
        self.frames_total = 0
        self.detections_total = 0

    def record(self, stage: str, now: float, ms: float) -> None:
        self._lat[stage].add(now, ms)
        if self._on_latency is not None:
            self._on_latency(stage, ms, self.camera)

    def on_detections(self, msg: Detections, now: float) -> None:
        stamp = msg.header.stamp_ns
        self.frames_total += 1
        self.detections_total += len(msg)
        self._frames.add(now, float(len(msg)))
        for stage in DETECTOR_STAGES:
            if stage in msg.timing_ms:
                self.record(stage, now, msg.timing_ms[stage])
        if msg.received_ns:
            self.record("capture_to_detector", now, (msg.received_ns - stamp) / NS_PER_MS)
        if msg.published_ns:
            self.record("capture_to_detections", now, (msg.published_ns - stamp) / NS_PER_MS)

    def on_reaction(self, now: float, captured: int, published: int, commanded: int) -> None:
        """The first command reacting to a frame captured at ``captured`` whose detections were
        published at ``published`` (all wall-clock ns)."""
        self.record("detections_to_command", now, (commanded - published) / NS_PER_MS)
        self.record("end_to_end", now, (commanded - captured) / NS_PER_MS)

    def fps(self, now: float) -> float:
        return self._frames.rate(now)

    def detections_per_frame(self, now: float) -> float:
        boxes = self._frames.values(now)
        return float(boxes.mean()) if boxes.size else 0.0

    def latency_ms(self, now: float) -> LatencyStats:
        return {stage: percentiles(w.values(now)) for stage, w in self._lat.items()}

    def latency_samples(self, now: float) -> dict[str, list[float]]:
        """Every latency sample still in the window, per stage, in arrival order (ms)."""
        return {stage: w.values(now).tolist() for stage, w in self._lat.items()}
