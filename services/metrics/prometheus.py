"""The metrics service's optional Prometheus endpoint (``metrics.prometheus_port``, 0 = off).

Two kinds of series, because they answer different questions:

* ``stack_latency_seconds{stage}``: a histogram fed with every latency sample as it arrives.
  It is cumulative since start, so Prometheus can compute any quantile over any range
  (``histogram_quantile(0.95, rate(stack_latency_seconds_bucket[5m]))``).
* gauges and counters read from the service's current answer at scrape time: FPS, detections
  per frame, drop rate, the window's own percentiles (``stack_latency_window_ms``), frame and
  detection totals, per-class detections and every service counter.

The depth figures: ``stack_depth_frames`` (depth images the detector took),
``stack_depth_unpaired`` (colour frames of a depth camera with no depth in time), per camera
too; the depth stage's time is the ``depth`` stage of the latency series.

Each camera's figures (the answer's ``cameras``) are the same series under ``stack_camera_*``
with a ``camera`` label (``stack_camera_latency_seconds{camera,stage}``, ``stack_camera_fps
{camera}`` ...); the series above stay every camera's together, as they were with one camera.

A private registry is used (not prometheus_client's global one) so that tests and several
exporters in one process never collide. No zenoh here: the service hands us its answer.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from wsgiref.simple_server import WSGIServer

from prometheus_client import CollectorRegistry, Histogram, start_http_server
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric

from common.contracts import MetricsAnswer
from common.errors import ConfigError

#: Histogram buckets in seconds: a CPU detector lives around 50-500 ms, a GPU one below 50 ms.
LATENCY_BUCKETS_S = (0.005, 0.01, 0.02, 0.035, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.5, 1.0, 2.0, 5.0)
_QUANTILES = ("p50", "p95", "p99", "mean")
#: Answer key -> help text; each becomes the gauge ``stack_<key>``.
_GAUGES = {
    "fps": "Detections messages per second over the window",
    "detections_per_frame": "Mean boxes per frame over the window",
    "drop_rate": "Frames the detector dropped / frames offered to it, over the window",
    "drop_rate_total": "Dropped / offered frames since the detector started",
    "window_s": "Span of the sliding window in seconds",
}

#: Camera figure -> help text; each becomes the gauge ``stack_camera_<key>{camera}``.
_CAMERA_GAUGES = {
    "fps": "Detections messages per second over the window, per camera",
    "detections_per_frame": "Mean boxes per frame over the window, per camera",
    "drop_rate": "Frames dropped / offered over the window, per camera",
    "drop_rate_total": "Frames dropped / offered since the worker started, per camera",
    "batch_mean": "Mean frames per inference run of the worker serving the camera (window)",
}
#: Camera total -> help text; each becomes the counter ``stack_camera_<key>{camera}``.
_CAMERA_COUNTERS = {
    "frames": "Detections messages seen, per camera",
    "detections": "Boxes seen, per camera",
    "dropped_frames": "Frames the worker dropped, per camera",
    "frames_offered": "Frames offered to the worker, per camera",
    "depth_frames": "Depth images the worker took, per camera",
    "depth_unpaired": "Colour frames with no depth image in time, per camera",
}
#: Answer total -> help text; each becomes the counter ``stack_<key>``.
_COUNTERS = {
    "frames": "Detections messages seen",
    "detections": "Boxes seen in all detections",
    "depth_frames": "Depth images the detector took",
    "depth_unpaired": "Colour frames of a depth camera with no depth image in time",
}

#: Returns the metrics query's JSON answer, taken under the service's lock.
AnswerSource = Callable[[], MetricsAnswer]


class _AnswerCollector:
    """Turns the current answer into gauges and counters at each scrape."""

    def __init__(self, source: AnswerSource) -> None:
        self._source = source

    def collect(self) -> Iterator[Metric]:
        a = self._source()
        for key, doc in _GAUGES.items():
            value = a.get(key, 0.0)
            yield GaugeMetricFamily(
                f"stack_{key}", doc, value=float(value) if isinstance(value, int | float) else 0.0
            )
        window = GaugeMetricFamily(
            "stack_latency_window_ms",
            "Latency percentiles over the sliding window, per stage (ms)",
            labels=["stage", "quantile"],
        )
        for stage, pct in a.get("latency_ms", {}).items():
            for q in _QUANTILES:
                window.add_metric([stage, q], float(pct.get(q, 0.0)))
        yield window
        for key, doc in _COUNTERS.items():
            total = a.get(key, 0)
            yield CounterMetricFamily(f"stack_{key}", doc, value=float(total))  # type: ignore[arg-type]
        classes = CounterMetricFamily(
            "stack_class_detections", "Boxes seen per class", labels=["class_name"]
        )
        for name, count in a.get("class_counts", {}).items():
            classes.add_metric([name], float(count))
        yield classes
        events = CounterMetricFamily(
            "stack_service_events",
            "Each service's own counters (frames_in, dropped, bad_input ...) since it started",
            labels=["service", "counter"],
        )
        for key, count in a.get("counters", {}).items():
            service, _, counter = key.partition(".")
            events.add_metric([service, counter], float(count))
        yield events
        yield from _camera_metrics(a)


def _camera_metrics(a: MetricsAnswer) -> Iterator[Metric]:
    """Each camera's figures, labelled ``camera``."""
    cameras = a.get("cameras", {})
    for key, doc in _CAMERA_GAUGES.items():
        gauge = GaugeMetricFamily(f"stack_camera_{key}", doc, labels=["camera"])
        for camera, figures in cameras.items():
            gauge.add_metric([camera], float(figures[key]))  # type: ignore[literal-required]
        yield gauge
    for key, doc in _CAMERA_COUNTERS.items():
        counter = CounterMetricFamily(f"stack_camera_{key}", doc, labels=["camera"])
        for camera, figures in cameras.items():
            counter.add_metric([camera], float(figures.get(key, 0)))  # type: ignore[arg-type]
        yield counter
    served = GaugeMetricFamily(
        "stack_camera_served_by",
        "1 for the worker serving each camera",
        labels=["camera", "worker"],
    )
    window = GaugeMetricFamily(
        "stack_camera_latency_window_ms",
        "Latency percentiles over the sliding window, per camera and stage (ms)",
        labels=["camera", "stage", "quantile"],
    )
    events = CounterMetricFamily(
        "stack_camera_service_events",
        "Each service's counters for one camera (<name>.<camera>) since it started",
        labels=["camera", "service", "counter"],
    )
    for camera, figures in cameras.items():
        if figures["served_by"]:
            served.add_metric([camera, figures["served_by"]], 1.0)
        for stage, pct in figures["latency_ms"].items():
            for q in _QUANTILES:
                window.add_metric([camera, stage, q], float(pct.get(q, 0.0)))
        for key, count in figures["counters"].items():
            service, _, counter_name = key.partition(".")
            events.add_metric([camera, service, counter_name], float(count))
    yield served
    yield window
    yield events


class PrometheusExporter:
    """A histogram fed by :meth:`observe` plus the answer's gauges, served over HTTP."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self._latency = Histogram(
            "stack_latency_seconds",
            "Latency per stage (capture_to_detector ... end_to_end), every sample since start",
            ["stage"],
            buckets=LATENCY_BUCKETS_S,
            registry=self.registry,
        )
        self._camera_latency = Histogram(
            "stack_camera_latency_seconds",
            "Latency per camera and stage, every sample since start",
            ["camera", "stage"],
            buckets=LATENCY_BUCKETS_S,
            registry=self.registry,
        )
        self._server: WSGIServer | None = None
        self._thread: threading.Thread | None = None

    def observe(self, stage: str, ms: float, camera: str = "") -> None:
        """Record one latency sample (ms, as the aggregator measures; exported in seconds):
        ``camera``'s, or every camera's together for ""."""
        if camera:
            self._camera_latency.labels(camera, stage).observe(ms / 1000.0)
        else:
            self._latency.labels(stage).observe(ms / 1000.0)

    def start(self, source: AnswerSource, host: str, port: int) -> int:
        """Serve ``http://host:port/metrics`` on a daemon thread; return the bound port.

        ``source`` gives the current answer at each scrape. Port 0 picks a free one (tests).
        A port in use is a bad configuration: ConfigError.
        """
        self.registry.register(_AnswerCollector(source))
        try:
            self._server, self._thread = start_http_server(port, host, registry=self.registry)
        except OSError as exc:
            raise ConfigError(
                f"metrics.prometheus_port: cannot listen on {host}:{port} ({exc.strerror or exc})"
            ) from exc
        return int(self._server.server_address[1])

    def close(self) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
