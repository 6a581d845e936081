"""The depth figures (issue 32): the depth images the detector took (``depth_in``), its colour
frames with no depth in time (``depth_unpaired``) and the depth stage's time
(``timing_ms["depth"]``), in the answer, per camera, in ``zstack query``'s lines and in
Prometheus; and each camera's depth flag and mounting as announced."""

from __future__ import annotations

import dataclasses
import urllib.request
from typing import Any

from prometheus_client.parser import text_string_to_metric_families

from common.messages import Detections, Header, ServiceCounters
from services.metrics.aggregate import Aggregator, report_line
from services.metrics.prometheus import PrometheusExporter
from services.metrics.summary import summary
from tests.unit.metrics.samples import detections
from tests.unit.metrics.test_service import Rig

MS = 1_000_000
HEADER = Header(stamp_ns=0, frame_id="", seq=0, source="metrics")
# Two pool workers: detector serves front (a depth camera), detector_2 serves rear (none).
WORKERS = {
    "detector": {"frames_in.front": 10, "serving.front": 1, "depth_in": 9, "depth_in.front": 9,
                 "depth_unpaired": 1, "depth_unpaired.front": 1},
    "detector_2": {"frames_in.rear": 5, "serving.rear": 1, "depth_in": 2, "depth_unpaired": 3},
}  # fmt: skip


def _with_depth(stamp: int, seq: int, depth_ms: float | None) -> Detections:
    dets = detections(Header(stamp_ns=stamp, frame_id="c", seq=seq, source="camera"), 1)
    if depth_ms is None:
        return dets  # a colour frame that found no depth in time: no depth stage
    return dataclasses.replace(dets, timing_ms={**dets.timing_ms, "depth": depth_ms})


def _aggregator(on_latency: Any = None) -> Aggregator:
    agg = Aggregator(window_s=10.0, cameras=("front", "rear"), on_latency=on_latency)
    for i, ms in enumerate((3.0, 4.0, 5.0, None)):
        agg.on_detections(_with_depth(1_000 * MS + i * 100 * MS, i, ms), i * 0.1, camera="front")
    agg.on_detections(_with_depth(1_001 * MS, 9, None), 0.3, camera="rear")
    for service, counts in WORKERS.items():
        msg = ServiceCounters(header=HEADER, service=service, counters=counts)
        agg.on_counters(msg, now=0.5)
    return agg


def test_the_answer_has_the_depth_figures_in_all_and_per_camera() -> None:
    agg = _aggregator()
    answer = agg.answer(HEADER, now=1.0)
    assert (answer["depth_frames"], answer["depth_unpaired"]) == (11, 4)  # both workers
    depth = answer["latency_ms"]["depth"]
    assert (depth["p50"], depth["count"]) == (4.0, 3.0)  # only the frames that had depth
    front, rear = answer["cameras"]["front"], answer["cameras"]["rear"]
    assert (front["depth_frames"], front["depth_unpaired"]) == (9, 1)  # its worker's
    assert (rear["depth_frames"], rear["depth_unpaired"]) == (0, 0)
    assert front["latency_ms"]["depth"]["p50"] == 4.0
    assert rear["latency_ms"]["depth"]["count"] == 0.0
    assert "depth p50 4.0 ms | depth unpaired 4 |" in report_line(agg.snapshot(HEADER, 1.0))


def test_no_depth_no_depth_words() -> None:
    agg = Aggregator(window_s=10.0)
    agg.on_detections(_with_depth(1_000 * MS, 1, None), 0.0, camera="front")
    answer = agg.answer(HEADER, now=1.0)
    assert (answer["depth_frames"], answer["depth_unpaired"]) == (0, 0)
    assert "depth" not in report_line(agg.snapshot(HEADER, 1.0))
    assert summary(answer, "stack") == []


def test_the_announced_depth_and_mounting_and_the_query_lines() -> None:
    rig = Rig()
    try:
        rig.sources.announce(
            "front", depth=True, mount_x_m=0.2, mount_y_m=-0.1, mount_height_m=0.45
        )
        stamp = rig.clock.wall_ns()
        dets = _with_depth(stamp, 1, 6.0)
        rig.put(rig.keys.detections("front"), dataclasses.replace(
            dets, header=rig.header("front", 1, stamp)).encode())  # fmt: skip
        rig.counters("detector", frames_in__front=1, depth_in=1, depth_in__front=1,
                     depth_unpaired=0)  # fmt: skip
        answer = rig.query()
    finally:
        rig.close()
    front = answer["cameras_announced"]["front"]
    assert front["depth"] is True
    assert (front["mount_x_m"], front["mount_y_m"], front["mount_height_m"]) == (0.2, -0.1, 0.45)
    assert answer["cameras_announced"]["rear"]["depth"] is False
    assert answer["depth_frames"] == 1 and answer["cameras"]["front"]["depth_frames"] == 1
    lines = summary(answer, "stack")
    [camera] = [line for line in lines if line.startswith("  front ")]
    assert camera.endswith("  depth  at x +0.20 y -0.10 height 0.45 m"), camera
    [rear] = [line for line in lines if line.startswith("  rear ")]
    assert "depth" not in rear and " at x " not in rear, rear
    assert (
        "depth: 1 depth images, 0 colour frames without depth in time, "
        "depth stage p50 6.0 ms p95 6.0 ms"
    ) in lines
    assert "  front: 1 depth images, 0 without depth" in lines


def test_prometheus_has_the_depth_series() -> None:
    exporter = PrometheusExporter()
    agg = _aggregator(exporter.observe)
    port = exporter.start(lambda: agg.answer(HEADER, now=1.0), "127.0.0.1", 0)
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=10) as reply:
            text = reply.read().decode()
    finally:
        exporter.close()
    samples: dict[str, list[tuple[dict[str, str], float]]] = {}
    for family in text_string_to_metric_families(text):
        for s in family.samples:
            samples.setdefault(s.name, []).append((s.labels, s.value))

    def value(name: str, **labels: str) -> float:
        return next(v for lab, v in samples[name] if labels.items() <= lab.items())

    assert value("stack_depth_frames_total") == 11
    assert value("stack_depth_unpaired_total") == 4
    assert value("stack_camera_depth_frames_total", camera="front") == 9
    assert value("stack_camera_depth_unpaired_total", camera="front") == 1
    assert value("stack_latency_seconds_count", stage="depth") == 3
    assert value("stack_latency_window_ms", stage="depth", quantile="p50") == 4.0
    assert value("stack_camera_latency_seconds_count", camera="front", stage="depth") == 3


def test_an_answer_from_before_depth_still_prints() -> None:
    older: Any = {"cameras_announced": {"front": {
        "width": 640, "height": 480, "rate_hz": 10.0, "mount_yaw_deg": 0.0, "hfov_deg": 60.0,
        "frame_id": "camera", "source": "sim"}}, "latency_ms": {}, "warnings": {}}  # fmt: skip
    [_, camera] = summary(older, "stack")
    assert "depth" not in camera and " at x " not in camera, camera
