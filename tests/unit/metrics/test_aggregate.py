from __future__ import annotations

import numpy as np
import pytest

from common.messages import Detections, Header, ServiceCounters, Twist
from services.metrics.aggregate import Aggregator
from services.metrics.window import Window, percentiles
from tests.unit.metrics.samples import detections

MS = 1_000_000


def _dets(stamp: int, n: int) -> Detections:
    return detections(Header(stamp_ns=stamp, frame_id="c", seq=stamp, source="camera"), n)


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
        agg.on_detections(_dets(stamp, n=i % 3), now=i * 0.1, camera="front")
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
        ServiceCounters(header=hdr, service="detector", counters={"dropped": 7, "bad_input": 2}),
        now=0.0,
    )
    agg.count("bad_input")
    snap = agg.snapshot(hdr, now=0.0)
    assert snap.dropped_frames == 7
    assert snap.counters == {"detector.bad_input": 2, "detector.dropped": 7, "metrics.bad_input": 1}


HDR = Header(stamp_ns=0, frame_id="", seq=0, source="metrics")


def _counters(frames_in: int, dropped: int) -> ServiceCounters:
    hdr = Header(stamp_ns=0, frame_id="", seq=0, source="detector")
    return ServiceCounters(
        header=hdr, service="detector", counters={"frames_in": frames_in, "dropped": dropped}
    )


def test_drop_rate_over_the_window_and_since_start() -> None:
    agg = Aggregator(window_s=5.0)
    agg.on_counters(_counters(100, 50), now=0.0)  # a baseline: what came before is not in it
    agg.on_counters(_counters(110, 52), now=1.0)
    agg.on_counters(_counters(120, 58), now=2.0)
    extras = agg.answer(HDR, now=2.5)
    assert extras["drop_rate"] == pytest.approx(8 / 20)
    assert extras["drop_rate_total"] == pytest.approx(58 / 120)
    assert extras["frames_offered"] == 120
    # A restarted detector counts from zero again; its new counts are deltas, not negatives.
    agg.on_counters(_counters(10, 1), now=3.0)
    assert agg.answer(HDR, now=3.5)["drop_rate"] == pytest.approx(9 / 30)
    assert agg.answer(HDR, now=20.0)["drop_rate"] == 0.0  # everything has left the window


def test_timeline_gives_fps_and_boxes_per_second() -> None:
    agg = Aggregator(window_s=10.0, history_s=60.0)
    for i in range(30):  # 10 frames per second for 3 s, 2 boxes each
        agg.on_detections(_dets(1_000 * MS + i * 100 * MS, n=2), now=10.0 + i * 0.1, camera="front")
    agg.on_counters(_counters(0, 0), now=10.0)
    agg.on_counters(_counters(60, 30), now=13.0)  # 20 offered/s, 10 dropped/s, over 3 s
    tl = agg.answer(HDR, now=15.5, clock_to_unix=1000.0)["timeline"]
    assert tl["t"] == [1010.0, 1011.0, 1012.0]  # up to 2 s ago: counters may still come
    assert tl["fps"] == [10.0, 10.0, 10.0]
    assert tl["detections_per_frame"] == [2.0, 2.0, 2.0]
    assert tl["offered_fps"] == pytest.approx([20.0, 20.0, 20.0])
    assert tl["dropped"] == pytest.approx([10.0, 10.0, 10.0])


def test_latency_listener_sees_every_sample() -> None:
    seen: list[tuple[str, float, str]] = []
    agg = Aggregator(
        window_s=10.0, on_latency=lambda stage, ms, camera: seen.append((stage, ms, camera))
    )
    agg.on_detections(_dets(1_000 * MS, n=1), now=0.0, camera="front")
    agg.on_twist(_twist(1_000 * MS + 95 * MS, 1_000 * MS), now=0.1)
    stages = {stage: ms for stage, ms, camera in seen if camera == ""}
    assert stages["inference"] == 80.0 and stages["end_to_end"] == pytest.approx(95.0)
    # Three detector stages, two transport figures, two command figures: once for the totals
    # (camera "") and once for the camera.
    assert sorted(camera for _, _, camera in seen) == [""] * 7 + ["front"] * 7


def test_answer_is_the_snapshot_plus_extras() -> None:
    agg = Aggregator(window_s=10.0)
    agg.on_detections(_dets(1_000 * MS, n=1), now=0.0, camera="front")
    answer = agg.answer(Header(stamp_ns=5, frame_id="", seq=0, source="metrics"), now=0.5)
    assert answer["frames"] == 1 and answer["stamp_ns"] == 5
    assert {"drop_rate", "drop_rate_total", "timeline"} <= answer.keys()
    assert agg.latency_samples(0.5)["inference"] == [80.0]


def test_a_command_that_overtakes_its_detections_is_still_paired() -> None:
    agg = Aggregator(window_s=10.0)
    stamp = 1_000 * MS
    agg.on_twist(_twist(stamp + 95 * MS, stamp), now=0.0)  # arrives first
    agg.on_twist(_twist(stamp + 145 * MS, stamp), now=0.0)  # a repeat: ignored
    agg.on_detections(_dets(stamp, n=1), now=0.0, camera="front")
    snap = agg.snapshot(Header(stamp_ns=0, frame_id="", seq=0, source="metrics"), now=0.1)
    assert snap.latency_ms["end_to_end"]["count"] == 1
    assert snap.latency_ms["end_to_end"]["p50"] == pytest.approx(95.0)
    assert snap.latency_ms["detections_to_command"]["p50"] == pytest.approx(5.0)
