from __future__ import annotations

import numpy as np
import pytest

from common.messages import Detections, Header, ServiceCounters, Twist
from services.metrics.aggregate import Aggregator
from services.metrics.window import Window, percentiles

MS = 1_000_000


def _dets(stamp: int, n: int) -> Detections:
    return Detections(
        header=Header(stamp_ns=stamp, frame_id="c", seq=stamp, source="camera"),
        image_width=640,
        image_height=480,
        class_ids=np.zeros(n, np.int32),
        class_names=("person",) * n,
        scores=np.ones(n, np.float32),
        xyxy=np.tile(np.array([0, 0, 10, 10], np.float32), (n, 1)),
        timing_ms={"preprocess": 2.0, "inference": 80.0, "postprocess": 1.0},
        received_ns=stamp + 5 * MS,
        published_ns=stamp + 90 * MS,
    )


def _twist(stamp: int, input_stamp: int) -> Twist:
    return Twist(
        header=Header(stamp_ns=stamp, frame_id="b", seq=1, source="controller"),
        input_stamp_ns=input_stamp,
    )


def test_percentiles_match_numpy() -> None:
    v = np.arange(1, 101, dtype=np.float64)
    p = percentiles(v)
    assert p["p50"] == pytest.approx(50.5) and p["p99"] == pytest.approx(99.01)
    assert p["count"] == 100
    assert percentiles(np.empty(0))["count"] == 0


def test_window_forgets_old_samples_and_measures_rate() -> None:
    w = Window(span_s=1.0)
    for i in range(30):
        w.add(i * 0.1, float(i))
    assert w.values(2.9).tolist() == [float(i) for i in range(19, 30)]
    assert w.rate(2.9) == pytest.approx(10.0)


def test_latency_chain_from_capture_to_command() -> None:
    agg = Aggregator(window_s=10.0)
    for i in range(10):
        stamp = 1_000 * MS + i * 100 * MS
        agg.on_detections(_dets(stamp, n=i % 3), now=i * 0.1)
        agg.on_twist(_twist(stamp + 95 * MS, stamp), now=i * 0.1)
        agg.on_twist(_twist(stamp + 145 * MS, stamp), now=i * 0.1)  # repeat: not a reaction
    snap = agg.snapshot(Header(stamp_ns=0, frame_id="", seq=0, source="metrics"), now=0.95)
    lat = snap.latency_ms
    assert lat["capture_to_detector"]["p50"] == pytest.approx(5.0)
    assert lat["capture_to_detections"]["p50"] == pytest.approx(90.0)
    assert lat["detections_to_command"]["p50"] == pytest.approx(5.0)
    assert lat["end_to_end"]["p50"] == pytest.approx(95.0)
    assert lat["end_to_end"]["count"] == 10
    assert lat["inference"]["p50"] == pytest.approx(80.0)
    assert snap.fps == pytest.approx(10.0)
    assert snap.frames == 10 and snap.detections == sum(i % 3 for i in range(10))
    assert snap.detections_per_frame == pytest.approx(snap.detections / 10)


def test_counters_are_namespaced_and_drops_surface() -> None:
    agg = Aggregator(window_s=5.0)
    hdr = Header(stamp_ns=0, frame_id="", seq=0, source="detector")
    agg.on_counters(
        ServiceCounters(header=hdr, service="detector", counters={"dropped": 7, "bad_input": 2})
    )
    agg.count("bad_input")
    snap = agg.snapshot(hdr, now=0.0)
    assert snap.dropped_frames == 7
    assert snap.counters == {"detector.bad_input": 2, "detector.dropped": 7, "metrics.bad_input": 1}
