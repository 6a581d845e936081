"""The metrics service: listens to detections, commands and counters; answers queries in JSON.

The answer is :meth:`Aggregator.answer`, a ``common.contracts.MetricsAnswer``: the snapshot's
figures plus drop rates and the per-second timeline, so the message schema stays as it is. With
``prometheus_port`` set the same figures are also served to Prometheus.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from common import reach
from common.bus import open_session
from common.clock import mono_s, mono_to_unix_s
from common.contracts import MetricsAnswer
from common.errors import DecodeError, StackError
from common.keys import Keys
from common.messages import Detections, ServiceCounters, Twist
from common.node import Node
from common.queries import query_metrics, ready_services
from common.settings import SERVICES, Config
from services.metrics.aggregate import Aggregator, LatencyListener, report_line
from services.metrics.trust import (
    refuse_counters,
    refuse_detections,
    split_counters,
    strict_json,
)

OBSERVER = "observer"  # the principal that asks: it may read and query, never put


def run(config: Config, stop: threading.Event) -> int:
    """Serve metrics until ``stop`` is set."""
    s = config.metrics
    lock = threading.Lock()  # Zenoh calls back on its own threads
    now = mono_s
    exporter = None
    listener: LatencyListener | None = None
    if s.prometheus_port:
        from services.metrics.prometheus import PrometheusExporter  # only when asked for

        exporter = PrometheusExporter()
        listener = exporter.observe
    agg = Aggregator(
        s.window_s,
        s.history_s,
        on_latency=listener,
        max_counters_per_service=s.max_counters_per_service,
        max_classes=s.max_classes,
    )
    with Node("metrics", config) as node:

        def answer() -> MetricsAnswer:
            with lock:
                return agg.answer(node.header(), now(), mono_to_unix_s())

        def handler(
            key: str,
            decode: Callable[[bytes], Any],
            feed: Callable[[Any], None],
            refuse: Callable[[Any, str], str | None] = lambda _m, _k: None,
        ) -> Any:
            def on_sample(sample: zenoh.Sample) -> None:
                try:
                    msg = decode(sample.payload.to_bytes())
                except DecodeError as exc:
                    node.bad_input(key, exc)
                    with lock:
                        agg.count("bad_input")
                    return
                heard_on = str(sample.key_expr)
                why = refuse(msg, heard_on)
                if why is not None:
                    node.reject(f"refused.{why}", f"{key} on {heard_on} refused: {why}", key=key)
                    with lock:
                        agg.count(f"refused.{why}")
                    return
                with lock:
                    feed(msg)

            return on_sample

        def refuse_counters_of(msg: ServiceCounters, heard_on: str) -> str | None:
            return refuse_counters(msg, heard_on, SERVICES, s.max_counters_per_service)

        def feed_counters(msg: ServiceCounters) -> None:
            kept, refused = split_counters(msg)
            for why, n in refused.items():
                agg.count(f"refused.{why}", n)
                node.reject(f"refused.{why}", f"{n} of {msg.service}'s counters refused: {why}")
            agg.on_counters(kept, now())

        keys = node.keys
        subs = [
            node.session.declare_subscriber(
                keys.all_detections(),
                handler(
                    "detections",
                    Detections.decode,
                    lambda m: agg.on_detections(m, now()),
                    lambda m, _k: refuse_detections(m, s.max_timing_ms),
                ),
            ),
            node.session.declare_subscriber(
                keys.cmd_vel(), handler("cmd_vel", Twist.decode, lambda m: agg.on_twist(m, now()))
            ),
            node.session.declare_subscriber(
                keys.all_counters(),
                handler("counters", ServiceCounters.decode, feed_counters, refuse_counters_of),
            ),
        ]

        def on_query(query: zenoh.Query) -> None:
            query.reply(
                keys.metrics(), strict_json(answer()), encoding=zenoh.Encoding.APPLICATION_JSON
            )

        queryable = node.session.declare_queryable(keys.metrics(), on_query)
        if exporter is not None:
            port = exporter.start(answer, s.prometheus_host, s.prometheus_port)
            node.log.info("prometheus metrics on http://%s:%d/metrics", s.prometheus_host, port)
        node.ready()
        try:
            while not stop.wait(s.report_period_s):
                with lock:
                    snap = agg.snapshot(node.header(), now())
                node.log.info("%s", report_line(snap))
        finally:
            if exporter is not None:
                exporter.close()
            queryable.undeclare()
            for sub in subs:
                sub.undeclare()
    return 0


def query(config: Config, timeout_s: float) -> MetricsAnswer:
    """Ask the metrics service for its snapshot. Nobody answering within the timeout is a
    StackError naming where it looked and the likely fix (common/reach.py)."""
    session = open_session(config.zenoh, OBSERVER)
    keys = Keys(config.stack.prefix)
    try:
        deadline = mono_s() + timeout_s
        while mono_s() < deadline:
            answer = query_metrics(session, keys, 1.0)
            if answer is not None:
                return answer
            time.sleep(0.2)  # the peer mesh may still be forming; ask again
        linked = reach.connected(session)
        ready = frozenset(ready_services(session, keys)) if linked else frozenset()
        raise StackError(
            reach.unreached(
                f"no metrics service answered within {timeout_s:.0f} s",
                config.zenoh,
                config.stack.prefix,
                OBSERVER,
                linked=linked,
                ready=ready,
            )
        )
    finally:
        session.close()
