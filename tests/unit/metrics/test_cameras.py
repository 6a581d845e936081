"""The aggregator with two cameras: each camera's figures apart, the totals together."""

from __future__ import annotations

import pytest

from common.messages import Detections, Header, ServiceCounters, Twist
from services.metrics.aggregate import Aggregator
from services.metrics.cameras import BatchSizes
from services.metrics.reactions import Reactions
from tests.unit.metrics.samples import detections

MS = 1_000_000
HDR = Header(stamp_ns=0, frame_id="", seq=0, source="metrics")


def _dets(stamp: int, n: int, published_ms: float = 90.0) -> Detections:
    header = Header(stamp_ns=stamp, frame_id="cam", seq=1, source="camera")
    return detections(header, n, published_ms=published_ms)


def _twist(stamp: int, input_stamp: int) -> Twist:
    return Twist(
        header=Header(stamp_ns=stamp, frame_id="base", seq=1, source="controller"),
        input_stamp_ns=input_stamp,
    )


def _counters(service: str, **counts: int) -> ServiceCounters:
    # Keyword names cannot hold a dot: "frames_in__rear" stands for "frames_in.rear".
    named = {name.replace("__", "."): n for name, n in counts.items()}
    return ServiceCounters(header=HDR, service=service, counters=named)


def test_each_camera_has_its_own_rate_boxes_and_latency() -> None:
    agg = Aggregator(window_s=10.0, cameras=("front", "rear"))
    for i in range(20):
        # front: 10 Hz, 2 boxes, reacted to 95 ms after capture
        stamp = 1_000 * MS + i * 100 * MS
        agg.on_detections(_dets(stamp, 2), now=i * 0.1, camera="front")
        agg.on_twist(_twist(stamp + 95 * MS, stamp), now=i * 0.1)
        if i % 2 == 0:  # rear: 5 Hz, 1 box, slower to publish, reacted to 250 ms after
            stamp += 3 * MS
            agg.on_detections(_dets(stamp, 1, published_ms=200.0), now=i * 0.1, camera="rear")
            agg.on_twist(_twist(stamp + 250 * MS, stamp), now=i * 0.1)
    answer = agg.answer(HDR, now=1.95)
    front, rear = answer["cameras"]["front"], answer["cameras"]["rear"]
    assert list(answer["cameras"]) == ["front", "rear"]
    assert front["fps"] == pytest.approx(10.0)
    assert rear["fps"] == pytest.approx(9 / 1.8)  # 10 frames, 0 to 1.8 s
    assert (front["frames"], front["detections"]) == (20, 40)
    assert (rear["frames"], rear["detections"]) == (10, 10)
    assert front["detections_per_frame"] == 2.0 and rear["detections_per_frame"] == 1.0
    assert front["latency_ms"]["end_to_end"]["p50"] == pytest.approx(95.0)
    assert rear["latency_ms"]["end_to_end"]["p50"] == pytest.approx(250.0)
    assert rear["latency_ms"]["detections_to_command"]["p50"] == pytest.approx(50.0)
    assert rear["latency_ms"]["capture_to_detections"]["p50"] == pytest.approx(200.0)
    assert front["latency_ms"]["end_to_end"]["count"] == 20
    assert rear["latency_ms"]["end_to_end"]["count"] == 10
    # The top level is every camera together, as it was with one camera.
    assert (answer["frames"], answer["detections"]) == (30, 50)
    assert answer["latency_ms"]["end_to_end"]["count"] == 30
    assert answer["fps"] == pytest.approx(29 / 1.9)


def test_a_command_for_a_stamp_both_cameras_share_counts_for_each_and_once_in_total() -> None:
    agg = Aggregator(window_s=10.0, cameras=("front", "rear"))
    stamp = 5_000 * MS
    agg.on_detections(_dets(stamp, 1, published_ms=80.0), now=0.0, camera="front")
    agg.on_twist(_twist(stamp + 100 * MS, stamp), now=0.1)
    agg.on_detections(_dets(stamp, 1, published_ms=90.0), now=0.1, camera="rear")  # after it
    agg.on_twist(_twist(stamp + 150 * MS, stamp), now=0.2)  # a repeat: no reaction
    cameras = agg.answer(HDR, now=0.3)["cameras"]
    for name, d2c in (("front", 20.0), ("rear", 10.0)):
        lat = cameras[name]["latency_ms"]
        assert lat["end_to_end"]["count"] == 1 and lat["end_to_end"]["p50"] == pytest.approx(100)
        assert lat["detections_to_command"]["p50"] == pytest.approx(d2c)
    total = agg.snapshot(HDR, now=0.3).latency_ms
    assert total["end_to_end"]["count"] == 1  # one frame, one reaction
    assert total["detections_to_command"]["p50"] == pytest.approx(20.0)  # from the first out


def test_counters_named_for_a_camera_show_under_it() -> None:
    agg = Aggregator(window_s=5.0, cameras=("front", "rear"))
    names = (
        "frames_in", "dropped", "batches", "batched_frames", "frames_in__front",
        "dropped__front", "frames_in__rear", "dropped__rear", "detections_out__rear",
        "frames_in__side",
    )  # fmt: skip
    for now, counts in (
        (0.0, (150, 60, 50, 100, 100, 50, 50, 10, 40, 7)),
        (2.0, (190, 70, 70, 140, 130, 58, 60, 12, 48, 9)),
    ):
        agg.on_counters(_counters("detector", **dict(zip(names, counts, strict=True))), now=now)
    agg.on_counters(_counters("controller", detections_in__rear=47, estop_in=1), now=2.0)
    answer = agg.answer(HDR, now=2.5)
    front, rear = answer["cameras"]["front"], answer["cameras"]["rear"]
    assert front["served_by"] == rear["served_by"] == "detector"
    assert (front["frames_offered"], front["dropped_frames"]) == (130, 58)
    assert (rear["frames_offered"], rear["dropped_frames"]) == (60, 12)
    assert front["drop_rate"] == pytest.approx(8 / 30)  # over the window: since the baseline
    assert rear["drop_rate"] == pytest.approx(2 / 10)
    assert rear["drop_rate_total"] == pytest.approx(12 / 60)
    assert front["batch_mean"] == rear["batch_mean"] == pytest.approx(40 / 20)
    assert rear["counters"] == {
        "controller.detections_in": 47,
        "detector.detections_out": 48,
        "detector.dropped": 12,
        "detector.frames_in": 60,
    }
    assert "side" not in answer["cameras"]  # not a camera of this stack: counters only
    assert answer["counters"]["detector.frames_in.side"] == 9
    # The top level keeps the detector's totals, as before.
    assert (answer["frames_offered"], answer["dropped_frames"]) == (190, 70)


def test_a_camera_without_detections_shows_zeros_and_extra_cameras_are_bounded() -> None:
    agg = Aggregator(window_s=5.0, cameras=("front", "rear"), max_cameras=2)
    agg.on_detections(_dets(1_000 * MS, 1), now=0.0, camera="front")
    agg.on_detections(_dets(1_100 * MS, 1), now=0.1, camera="made_up")  # no room for it
    answer = agg.answer(HDR, now=0.2)
    assert list(answer["cameras"]) == ["front", "rear"]
    rear = answer["cameras"]["rear"]
    assert (rear["fps"], rear["frames"], rear["served_by"], rear["batch_mean"]) == (0, 0, "", 0)
    assert answer["frames"] == 2  # the totals still count it
    assert answer["counters"]["metrics.cameras_refused"] == 1


def test_batch_mean_covers_the_window_and_survives_a_restart() -> None:
    batches = BatchSizes(window_s=5.0)
    assert batches.mean("detector") == 0.0
    batches.on_counters("detector", {"batches": 10, "batched_frames": 30}, now=0.0)
    assert batches.mean("detector") == 3.0  # one report: since the worker started
    batches.on_counters("detector", {"batches": 20, "batched_frames": 40}, now=3.0)
    assert batches.mean("detector") == 1.0  # 10 runs, 10 frames since the first report
    batches.on_counters("detector", {"batches": 25, "batched_frames": 50}, now=7.0)
    assert batches.mean("detector") == 20 / 15  # from the last report before the window, at 0 s
    batches.on_counters("detector", {"batches": 30, "batched_frames": 60}, now=9.0)
    assert batches.mean("detector") == 2.0  # from the report at 3 s: the one at 0 s is gone
    batches.on_counters("detector", {"batches": 2, "batched_frames": 8}, now=10.0)  # restarted
    assert batches.mean("detector") == 4.0
    batches.on_counters("controller", {"commands_out": 3}, now=8.0)  # no batches: ignored
    assert batches.mean("controller") == 0.0


def test_reactions_remember_a_bounded_number_of_frames() -> None:
    reactions = Reactions(keep=2)
    assert reactions.on_command(1, 10) == []  # before its detections
    reactions.on_detections("front", 2, 20)
    reactions.on_detections("front", 3, 30)  # frame 1 is forgotten
    assert reactions.on_detections("front", 1, 11) == []  # remembered anew, with no command
    scored = reactions.on_command(3, 35)
    assert [(r.camera, r.published, r.commanded, r.first) for r in scored] == [
        ("front", 30, 35, True)
    ]
