"""The metrics service: listens to detections, commands and counters; answers queries in JSON.

The answer is :meth:`Aggregator.answer`, a ``common.contracts.MetricsAnswer``: the snapshot's
figures plus drop rates and the per-second timeline, so the message schema stays as it is. With
``prometheus_port`` set the same figures are also served to Prometheus.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from functools import partial
from typing import TypeVar

from common import reach
from common.clock import mono_s, mono_to_unix_s
from common.contracts import MetricsAnswer
from common.counters import BAD_INPUT
from common.errors import DecodeError, StackError
from common.keys import Keys
from common.messages import Detections, ServiceCounters, Twist
from common.node import Node, Tally
from common.pool_audit import MAX_LINES, PoolAudit, lines
from common.pool_rule import camera_weights
from common.queries import query_metrics, ready_services
from common.settings import SERVICES
from common.zenoh_bus import open_session
from services.metrics import contract
from services.metrics.advice import advise
from services.metrics.aggregate import Aggregator, LatencyListener, report_line
from services.metrics.pool import LivePool
from services.metrics.trust import (
    PoolWorkers,
    refuse_counters,
    refuse_detections,
    split_counters,
    strict_json,
)
from stack.config import Config

_M = TypeVar("_M")

OBSERVER = "observer"  # the principal that asks: it may read and query, never put


class MetricsHandlers:
    """What the metrics service does with each message: decode it, refuse what it cannot trust
    (services/metrics/trust.py), feed the rest to the aggregator. Zenoh calls back on its own
    threads: the aggregator is only touched under ``lock``."""

    def __init__(
        self, config: Config, tally: Tally, on_latency: LatencyListener | None = None
    ) -> None:
        s = self.settings = config.metrics
        self.tally = tally
        d = config.detector
        self.pool = LivePool(
            PoolAudit(camera_weights(config.all_cameras), d.pool_balance, d.pool_alarm_s)
        )
        self.agg = Aggregator(
            s.window_s,
            s.history_s,
            on_latency=on_latency,
            max_counters_per_service=s.max_counters_per_service,
            max_classes=s.max_classes,
            cameras=config.all_cameras,
            pool=self.pool,
        )
        #: The services whose counters are believed: this stack's (camera_<name> and the
        #: detector workers too) and, bounded, any other detector worker: another host's.
        self.known = frozenset(
            (*SERVICES, *config.camera_services.values(), *config.detector_services)
        )
        self.pool_workers = PoolWorkers(s.max_workers)
        self.lock = threading.Lock()

    def on_detections(self, camera: str, key: str, payload: bytes) -> None:
        """``camera``'s detections; ``key``: the one the sample came on (that camera's)."""
        max_timing_ms = self.settings.max_timing_ms
        self._take(
            "detections", Detections.decode, key, payload,
            lambda m: self.agg.on_detections(m, mono_s(), camera=camera),
            lambda m, _k: refuse_detections(m, max_timing_ms),
        )  # fmt: skip

    def on_pool_member(self, key: str, live: bool) -> None:
        """A detector worker's pool token came (``live``) or went."""
        with self.lock:
            self.pool.member(key.rsplit("/", 1)[-1], live=live)
        self.audit_pool()

    def on_pool_serving(self, key: str, live: bool) -> None:
        """A worker's serving token (common/keys.py::pool_serving) came or went."""
        token = self.tally.keys.pool_serving_parts(key)
        if token is None:
            return
        with self.lock:
            self.pool.serving(token, live=live)
        self.audit_pool()

    def audit_pool(self) -> None:
        """Check the pool's tokens (common/pool_audit.py): a WARNING for what has been wrong
        for ``detector.pool_alarm_s``, a line when it clears; the answer shows what holds."""
        now = mono_s()
        with self.lock:
            if not self.pool.heard:
                return
            report = self.pool.check(now)
        for line in lines(report.raised, now):
            self.tally.log.warning("pool: %s", line)
        for finding in report.cleared[:MAX_LINES]:
            self.tally.log.info("pool: no longer so: %s", finding.detail)

    def on_cmd_vel(self, payload: bytes) -> None:
        key = self.tally.keys.cmd_vel()
        self._take("cmd_vel", Twist.decode, key, payload, lambda m: self.agg.on_twist(m, mono_s()))

    def on_counters(self, key: str, payload: bytes) -> None:
        """``key``: the one the sample came on, which must name the service that counts."""
        limit = self.settings.max_counters_per_service

        def refuse(msg: ServiceCounters, heard_on: str) -> str | None:
            with self.lock:  # the other hosts' workers admitted so far
                return refuse_counters(msg, heard_on, self.known, limit, self.pool_workers)

        self._take("counters", ServiceCounters.decode, key, payload, self._feed_counters, refuse)

    def _feed_counters(self, msg: ServiceCounters) -> None:
        kept, refused = split_counters(msg)
        for why, n in refused.items():
            self.agg.count(contract.refused(why), n)
            self.tally.reject(
                contract.refused(why), f"{n} of {msg.service}'s counters refused: {why}"
            )
        self.agg.on_counters(kept, mono_s())

    def _take(
        self,
        name: str,
        decode: Callable[[bytes], _M],
        heard_on: str,
        payload: bytes,
        feed: Callable[[_M], None],
        refuse: Callable[[_M, str], str | None] = lambda _m, _k: None,
    ) -> None:
        try:
            msg = decode(payload)
        except DecodeError as exc:
            self.tally.bad_input(name, exc)
            with self.lock:
                self.agg.count(BAD_INPUT)
            return
        why = refuse(msg, heard_on)
        if why is not None:
            self.tally.reject(
                contract.refused(why), f"{name} on {heard_on} refused: {why}", key=name
            )
            with self.lock:
                self.agg.count(contract.refused(why))
            return
        with self.lock:
            feed(msg)


def run(config: Config, stop: threading.Event) -> int:
    """Serve metrics until ``stop`` is set."""
    s = config.metrics
    exporter = None
    listener: LatencyListener | None = None
    if s.prometheus_port:
        from services.metrics.prometheus import PrometheusExporter  # only when asked for

        exporter = PrometheusExporter()
        listener = exporter.observe
    with Node("metrics", config) as node:
        handlers = MetricsHandlers(config, node, listener)
        agg, lock = handlers.agg, handlers.lock

        def answer() -> MetricsAnswer:
            handlers.audit_pool()
            with lock:
                out = agg.answer(node.header(), mono_s(), mono_to_unix_s())
            out["warnings"] = advise(config, out)
            return out

        keys = node.keys
        # One subscriber per configured camera, so the camera is the one its key names;
        # detections for a camera the config does not name (anyone may put them in peer
        # mode) are not heard, so they cannot grow the answer.
        subs = [
            *(
                node.subscribe_keyed(
                    keys.detections(camera), partial(handlers.on_detections, camera)
                )
                for camera in config.all_cameras
            ),
            node.subscribe(keys.cmd_vel(), handlers.on_cmd_vel),
            node.subscribe_keyed(keys.all_counters(), handlers.on_counters),
        ]

        watches = [
            node.bus.watch_tokens(keys.all_pool_members(), handlers.on_pool_member),
            node.bus.watch_tokens(keys.all_pool_serving(), handlers.on_pool_serving),
        ]
        queryable = node.bus.serve(keys.metrics(), lambda _key, _q: strict_json(answer()).encode())
        if exporter is not None:
            port = exporter.start(answer, s.prometheus_host, s.prometheus_port)
            node.log.info("prometheus metrics on http://%s:%d/metrics", s.prometheus_host, port)
        node.ready()
        next_report = mono_s() + s.report_period_s
        try:
            while not stop.wait(min(s.report_period_s, config.detector.pool_alarm_s / 2)):
                handlers.audit_pool()
                if mono_s() < next_report:
                    continue
                next_report = mono_s() + s.report_period_s
                with lock:
                    snap = agg.snapshot(node.header(), mono_s())
                node.log.info("%s", report_line(snap))
        finally:
            if exporter is not None:
                exporter.close()
            queryable.undeclare()
            for sub in [*subs, *watches]:
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
