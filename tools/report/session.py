"""Record a session for the report: run the stack under the supervisor and listen to it.

The recorder subscribes to the same keys as the metrics service (detections, commands,
counters) and feeds its own :class:`Aggregator`, with a window as long as the session, so the
report gets every latency sample (histograms need samples, not percentiles) and the whole
per-second timeline. At the end it also asks the metrics service for its answer, kept in the
session as the service saw it. Recording starts once every service is ready, so model loading
and warm-up stay out of the figures.

A session is plain JSON (``session.json``) that ``report --from`` reads back.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, cast

import zenoh

from common.clock import mono_s, utc_now, wall_ns
from common.contracts import Session
from common.errors import ConfigError, DecodeError
from common.keys import Keys
from common.lifecycle import Progress
from common.machine import machine_info
from common.messages import Detections, Header, ServiceCounters, Twist
from common.queries import query_metrics
from common.settings import REPO_ROOT
from common.zenoh_bus import open_session
from services.metrics.aggregate import Aggregator
from stack.config import Config
from stack.config_file import load_config
from tools.launch import start_supervisor, stop_supervisor, wait_ready, write_config

SESSION_VERSION = 1
#: The recorder's window outlasts the session by this much, so no sample ever leaves it.
_WINDOW_MARGIN_S = 60.0
_STOP_MARGIN_S = 15.0  # on top of the supervisor's own stop_timeout_s
_QUERY_TIMEOUT_S = 2.0
_REQUIRED = {"version": int, "duration_s": float, "summary": dict, "latency_samples_ms": dict}


def _frames_source(config: Config) -> str:
    """Where the frames come from: the simulator or the camera service, with its settings."""
    services = config.supervisor.services
    if "sim" in services:
        sim = config.sim
        return (
            f"simulator, scenario {sim.scenario!r}, {sim.width}x{sim.height} "
            f"at {sim.camera_rate_hz:g} Hz"
        )
    if "camera" in services:
        c = config.camera
        size = "source size" if c.resize == (0, 0) else f"{c.resize[0]}x{c.resize[1]}"
        encoding = f"JPEG q{c.jpeg_quality}" if c.jpeg_quality else "raw bgr8"
        return f"camera {c.source!r} at {c.rate_hz:g} Hz, {size}, {encoding}"
    return "from outside this stack (no sim or camera service)"


def _config_summary(config: Config) -> dict[str, Any]:
    d, path = config.detector, Path(config.path).resolve()
    return {
        "config": str(path.relative_to(REPO_ROOT) if path.is_relative_to(REPO_ROOT) else path),
        "services": ", ".join(config.supervisor.services),
        "frames": _frames_source(config),
        "detector_model": d.model or "default (YOLOv5s COCO)",
        "detector_backend": d.backend,
        "detector_conf": d.conf,
        "controller_mode": config.controller.mode,
        "target_classes": ", ".join(config.controller.target_classes),
    }


def _query_metrics(session: zenoh.Session, keys: Keys) -> dict[str, Any] | None:
    answer = query_metrics(session, keys, _QUERY_TIMEOUT_S)
    if answer is None:
        return None
    # Without its timeline: the recorder has its own, from the same messages.
    return {k: v for k, v in answer.items() if k != "timeline"}


def _listen(
    session: zenoh.Session,
    keys: Keys,
    cameras: Iterable[str],
    agg: Aggregator,
    lock: threading.Lock,
) -> list[Any]:
    """Feed ``agg`` from the bus, each camera's detections as that camera's; garbage is
    skipped (the metrics service counts it)."""

    def handler(decode: Callable[[bytes], Any], feed: Callable[[Any, float], None]) -> Any:
        def on_sample(sample: zenoh.Sample) -> None:
            try:
                msg = decode(sample.payload.to_bytes())
            except DecodeError:
                return
            with lock:
                feed(msg, mono_s())

        return on_sample

    def detections_of(camera: str) -> Callable[[Detections, float], None]:
        return lambda msg, now: agg.on_detections(msg, now, camera=camera)

    return [
        *(
            session.declare_subscriber(
                keys.detections(camera), handler(Detections.decode, detections_of(camera))
            )
            for camera in cameras
        ),
        session.declare_subscriber(keys.cmd_vel(), handler(Twist.decode, agg.on_twist)),
        session.declare_subscriber(
            keys.all_counters(), handler(ServiceCounters.decode, agg.on_counters)
        ),
    ]


def record(
    config_path: str | None,
    duration_s: float,
    log_path: Path,
    stop: threading.Event,
    progress: Progress,
    startup_timeout_s: float = 180.0,
) -> Session:
    """Start the stack, wait until it is ready, record ``duration_s`` seconds, stop it.

    The supervisor's output goes to ``log_path``. Ctrl-C (``stop``) during the recording ends
    it early and keeps what was recorded.
    """
    if duration_s <= 0:
        raise ConfigError(f"--duration must be positive, got {duration_s}")
    config = load_config(config_path)
    keys = Keys(config.stack.prefix)
    with log_path.open("wb") as log:
        # The config as loaded, beside the log: the supervisor reads only that file.
        path = write_config(config, log_path.with_suffix(".toml"))
        proc = start_supervisor(path, log)  # its own session: our Ctrl-C is sent once
    try:
        session = open_session(config.zenoh, config.principal("observer"))
        try:
            progress(f"report: starting the stack ({config.path}); log in {log_path}")
            services = set(config.supervisor.services)
            wait_ready(
                session, keys, services, proc, startup_timeout_s, stop=stop, log_path=log_path
            )
            progress(f"report: recording {duration_s:.0f} s")
            lock = threading.Lock()
            span = duration_s + _WINDOW_MARGIN_S
            agg = Aggregator(span, span, cameras=config.all_cameras)
            subs = _listen(session, keys, config.all_cameras, agg, lock)
            start = mono_s()
            stop.wait(duration_s)
            with lock:
                session_data = snapshot_session(agg, start, mono_s())
            for sub in subs:
                sub.undeclare()
            has_metrics = "metrics" in config.supervisor.services
            service_answer = _query_metrics(session, keys) if has_metrics else None
        finally:
            session.close()
    finally:
        stop_supervisor(proc, config.supervisor.stop_timeout_s + _STOP_MARGIN_S)
        exit_code = proc.returncode
    session_data["config"] = _config_summary(config)
    session_data["machine"] = machine_info()
    session_data["metrics_service"] = service_answer
    session_data["supervisor_exit_code"] = exit_code
    return session_data


def snapshot_session(agg: Aggregator, start: float, now: float) -> Session:
    """The recorded part of a session: ``agg``'s answer and samples between ``start`` and
    ``now`` (its clock), timeline times in seconds since ``start``."""
    header = Header(stamp_ns=wall_ns(), frame_id="", seq=0, source="report")
    samples = agg.latency_samples(now)
    return Session(
        version=SESSION_VERSION,
        created=utc_now().isoformat(timespec="seconds"),
        duration_s=round(now - start, 3),
        detector={"model": agg.model, "backend": agg.backend},
        summary=agg.answer(header, now, clock_to_unix=-start),
        latency_samples_ms={k: [round(v, 3) for v in vs] for k, vs in samples.items()},
    )


def check_session(data: Any, source: str) -> Session:
    """``data`` if it looks like a session (version and the keys the report reads)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: not a session file (expected a JSON object)")
    for key, kind in _REQUIRED.items():
        value = data.get(key)
        ok = isinstance(value, int | float) if kind is float else isinstance(value, kind)
        if not ok or isinstance(value, bool):
            raise ConfigError(
                f"{source}: not a session file ('{key}' missing or not a {kind.__name__})"
            )
    if data["version"] != SESSION_VERSION:
        raise ConfigError(
            f"{source}: session version {data['version']}; this code reads {SESSION_VERSION}"
        )
    for key in ("latency_ms", "timeline"):
        if not isinstance(data["summary"].get(key), dict):
            raise ConfigError(f"{source}: not a session file (summary has no '{key}')")
    return cast(Session, data)
