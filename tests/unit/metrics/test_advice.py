"""The metrics answer's warnings: detections too late for the controller's dead-man."""

from __future__ import annotations

import dataclasses

from common.messages import Header, ServiceCounters
from services.controller.contract import ControllerSettings
from services.detector.contract import DetectorSettings
from services.metrics.advice import DEPTH_SECOND_STREAM, DETECTIONS_LATE, advise
from services.metrics.aggregate import Aggregator
from stack.config import Config
from tests.unit.metrics.samples import detections


def answer_for(published_ms: float, every_s: float, n: int = 20):  # type: ignore[no-untyped-def]
    """The answer after ``n`` detections of camera front, one every ``every_s``, each published
    ``published_ms`` after its capture."""
    agg = Aggregator(10.0, cameras=["front"])
    for i in range(n):
        t = i * every_s
        h = Header(stamp_ns=int(t * 1e9), frame_id="camera", seq=i, source="camera")
        agg.on_detections(detections(h, 1, published_ms=published_ms), t, camera="front")
    return agg.answer(Header(stamp_ns=1, frame_id="", seq=1, source="metrics"), n * every_s)


def test_detections_in_time_bring_no_warning() -> None:
    assert advise(Config(), answer_for(300.0, 0.2)) == {}


def test_detections_that_go_stale_before_the_next_are_said_with_figures_and_fixes() -> None:
    # 900 ms old when published, one every 200 ms: 1.1 s old before the next, over 1.0 s.
    text = advise(Config(), answer_for(900.0, 0.2))[DETECTIONS_LATE]
    assert "p50 900 ms" in text and "one every 200 ms" in text and "1000 ms" in text, text
    assert 'detector.profile = "fast"' in text and "detector.imgsz" in text, text
    assert "controller.detection_timeout_s of 1.4 s or more" in text, text
    assert "fewer cameras" not in text  # one camera


def test_only_the_fixes_not_yet_made_are_offered() -> None:
    config = Config(
        detector=DetectorSettings(profile="fast", imgsz=320),
        controller=ControllerSettings(detection_timeout_s=0.5),
    )
    text = advise(config, answer_for(450.0, 0.2))[DETECTIONS_LATE]
    assert "profile" not in text and "imgsz" not in text, text
    assert "controller.detection_timeout_s of 0.8 s or more" in text, text
    # A longer timeout is the fix: no warning then.
    longer = dataclasses.replace(config.controller, detection_timeout_s=1.0)
    assert advise(dataclasses.replace(config, controller=longer), answer_for(450.0, 0.2)) == {}


def test_too_few_detections_are_not_judged() -> None:
    assert advise(Config(), answer_for(900.0, 0.2, n=3)) == {}


def _three_cameras(priority: dict[str, int]):  # type: ignore[no-untyped-def]
    """front late (900 ms, one every 200 ms) and left seldom (one every 2 s, at a floor), both
    served by ``detector``, whose attention gauges are ``priority`` (camera -> 0/1)."""
    agg = Aggregator(10.0, cameras=["front", "left"])
    counters = {"serving.front": 1, "serving.left": 1, "attention_priority": sum(priority.values())}
    counters |= {f"attention_priority.{cam}": v for cam, v in priority.items()}
    hdr = Header(stamp_ns=0, frame_id="", seq=0, source="detector")
    agg.on_counters(ServiceCounters(header=hdr, service="detector", counters=counters), 0.0)
    for cam, every_s, n in (("front", 0.2, 40), ("left", 2.0, 5)):
        for i in range(n):
            t = i * every_s
            h = Header(stamp_ns=int(t * 1e9), frame_id=cam, seq=i, source="camera")
            agg.on_detections(detections(h, 1, published_ms=900.0), t, camera=cam)
    return agg.answer(Header(stamp_ns=1, frame_id="", seq=1, source="metrics"), 8.5)


def test_a_camera_at_the_attention_floor_is_not_judged_late() -> None:
    # front has priority, left is served at the floor by design: only front is said.
    text = advise(Config(), _three_cameras({"front": 1, "left": 0}))[DETECTIONS_LATE]
    assert "front: " in text and "left: " not in text, text
    # With nothing prioritised the rounds are fair, and a late camera is late.
    text = advise(Config(), _three_cameras({"front": 0}))[DETECTIONS_LATE]
    assert "front: " in text and "left: " in text, text


def test_a_second_depth_stream_on_a_cameras_key_is_warned_of_by_name() -> None:
    agg = Aggregator(10.0, cameras=["front", "rear"])
    header = Header(stamp_ns=1, frame_id="", seq=1, source="depthscan")
    counters = {
        "depth_second_stream": 1, "depth_second_stream.front": 1,
        "depth_second_stream.rear": 0, "depth_late.front": 143, "depth_foreign.front": 7,
    }  # fmt: skip
    agg.on_counters(ServiceCounters(header=header, service="depthscan", counters=counters), 1.0)
    answer = agg.answer(Header(stamp_ns=2, frame_id="", seq=2, source="metrics"), 2.0)
    text = advise(Config(), answer)[DEPTH_SECOND_STREAM]
    assert "camera front:" in text and "rear" not in text, text
    assert "143 late, 7 foreign" in text, text
    # The gauge back to 0 (the second stream gone): no warning.
    counters |= {"depth_second_stream": 0, "depth_second_stream.front": 0}
    agg.on_counters(ServiceCounters(header=header, service="depthscan", counters=counters), 2.0)
    answer = agg.answer(Header(stamp_ns=3, frame_id="", seq=3, source="metrics"), 3.0)
    assert DEPTH_SECOND_STREAM not in advise(Config(), answer)
