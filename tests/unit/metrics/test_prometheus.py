"""The Prometheus endpoint, scraped over loopback like Prometheus would."""

from __future__ import annotations

import urllib.request
from collections.abc import Iterator

import pytest
from prometheus_client.parser import text_string_to_metric_families

from common.messages import Detections, Header, ServiceCounters
from services.metrics.aggregate import Aggregator
from services.metrics.prometheus import PrometheusExporter
from tests.unit.metrics.samples import detections

MS = 1_000_000
HEADER = Header(stamp_ns=0, frame_id="", seq=0, source="metrics")


@pytest.fixture
def served() -> Iterator[tuple[Aggregator, int]]:
    exporter = PrometheusExporter()
    agg = Aggregator(window_s=10.0, on_latency=exporter.observe)
    port = exporter.start(lambda: agg.answer(HEADER, now=1.0), "127.0.0.1", 0)
    yield agg, port
    exporter.close()


def _scrape(port: int) -> dict[str, list[tuple[dict[str, str], float]]]:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=10) as reply:
        return _samples(reply.read().decode())


def _samples(text: str) -> dict[str, list[tuple[dict[str, str], float]]]:
    out: dict[str, list[tuple[dict[str, str], float]]] = {}
    for family in text_string_to_metric_families(text):
        for s in family.samples:
            out.setdefault(s.name, []).append((s.labels, s.value))
    return out


Samples = dict[str, list[tuple[dict[str, str], float]]]


def _value(samples: Samples, name: str, **labels: str) -> float:
    return next(v for lab, v in samples[name] if labels.items() <= lab.items())


def _detections(stamp: int, seq: int) -> Detections:
    header = Header(stamp_ns=stamp, frame_id="c", seq=seq, source="camera")
    return detections(header, 1, size=(64, 48))


def test_scrape_shows_gauges_counters_and_latency_histogram(
    served: tuple[Aggregator, int],
) -> None:
    agg, port = served
    for i in range(5):
        stamp = 1_000 * MS + i * 100 * MS
        agg.on_detections(_detections(stamp, i), now=i * 0.1, camera="front")
    agg.on_counters(
        ServiceCounters(header=HEADER, service="detector", counters={"dropped": 3}), now=0.5
    )
    samples = _scrape(port)
    assert _value(samples, "stack_fps") == pytest.approx(10.0)
    assert _value(samples, "stack_detections_per_frame") == 1.0
    assert _value(samples, "stack_frames_total") == 5
    assert _value(samples, "stack_class_detections_total", class_name="person") == 5
    events = "stack_service_events_total"
    assert _value(samples, events, service="detector", counter="dropped") == 3
    assert _value(samples, "stack_latency_window_ms", stage="inference", quantile="p50") == 80.0
    # Every sample went into the histogram, in seconds: 80 ms falls in the 0.1 s bucket.
    assert _value(samples, "stack_latency_seconds_count", stage="inference") == 5
    assert _value(samples, "stack_latency_seconds_bucket", stage="inference", le="0.075") == 0
    assert _value(samples, "stack_latency_seconds_bucket", stage="inference", le="0.1") == 5
    assert "stack_drop_rate" in samples


def test_each_cameras_series_carry_a_camera_label() -> None:
    exporter = PrometheusExporter()
    agg = Aggregator(window_s=10.0, on_latency=exporter.observe, cameras=("front", "rear"))
    port = exporter.start(lambda: agg.answer(HEADER, now=1.0), "127.0.0.1", 0)
    try:
        for i in range(5):
            stamp = 1_000 * MS + i * 100 * MS
            agg.on_detections(_detections(stamp, i), now=i * 0.1, camera="front")
            if i < 2:
                agg.on_detections(_detections(stamp + MS, i), now=i * 0.1, camera="rear")
        counts = {"frames_in.rear": 4, "dropped.rear": 2, "batches": 3, "batched_frames": 6}
        agg.on_counters(
            ServiceCounters(header=HEADER, service="detector", counters=counts), now=0.5
        )
        samples = _scrape(port)
    finally:
        exporter.close()
    # The series of old are every camera's together; each camera's are stack_camera_*.
    assert _value(samples, "stack_frames_total") == 7
    assert _value(samples, "stack_latency_seconds_count", stage="inference") == 7
    assert _value(samples, "stack_camera_frames_total", camera="front") == 5
    assert _value(samples, "stack_camera_frames_total", camera="rear") == 2
    assert _value(samples, "stack_camera_fps", camera="front") == pytest.approx(10.0)
    latency = "stack_camera_latency_seconds_count"
    assert _value(samples, latency, camera="rear", stage="inference") == 2
    window = "stack_camera_latency_window_ms"
    assert _value(samples, window, camera="rear", stage="inference", quantile="p50") == 80.0
    assert _value(samples, "stack_camera_dropped_frames_total", camera="rear") == 2
    assert _value(samples, "stack_camera_served_by", camera="rear", worker="detector") == 1
    assert _value(samples, "stack_camera_batch_mean", camera="rear") == 2.0
    events = "stack_camera_service_events_total"
    assert _value(samples, events, camera="rear", service="detector", counter="dropped") == 2


def test_a_port_in_use_is_a_config_error(served: tuple[Aggregator, int]) -> None:
    from common.errors import ConfigError

    _, port = served
    other = PrometheusExporter()
    with pytest.raises(ConfigError, match=f"cannot listen on 127.0.0.1:{port}"):
        other.start(dict, "127.0.0.1", port)
