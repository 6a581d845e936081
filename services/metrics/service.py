"""The metrics service: listens to detections, commands and counters; answers queries in JSON.

The answer is :meth:`Aggregator.answer`, a ``common.contracts.MetricsAnswer``: the snapshot's
figures plus drop rates and the per-second timeline, so the message schema stays as it is. With
``prometheus_port`` set the same figures are also served to Prometheus.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping, Sequence
from contextlib import ExitStack
from typing import Any, TypeVar

from common import reach
from common.announce import Announced, announced_cameras, announced_workers
from common.bus import Declared
from common.clock import SYSTEM_CLOCK, Clock, mono_s
from common.contracts import AnnouncedCamera, MetricsAnswer
from common.counters import BAD_INPUT
from common.errors import DecodeError, StackError
from common.keys import Keys, camera_in_key
from common.messages import (
    CameraAnnouncement,
    Detections,
    ServiceCounters,
    Twist,
    WorkerAnnouncement,
)
from common.node import Node, Tally
from common.pool_audit import MAX_LINES, PoolAudit, lines
from common.pool_delivery import Delivery
from common.pool_rule import PoolWorker, camera_rates, one_worker
from common.queries import query_metrics, ready_services
from common.settings import SERVICES
from common.zenoh_bus import ZenohBus, open_session
from services.metrics import contract
from services.metrics.advice import advise
from services.metrics.aggregate import Aggregator, LatencyListener, report_line
from services.metrics.pool import LivePool
from services.metrics.pool_view import pool_view
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
        self,
        config: Config,
        tally: Tally,
        on_latency: LatencyListener | None = None,
        *,
        clock: Clock = SYSTEM_CLOCK,
    ) -> None:
        s = self.settings = config.metrics
        self.tally = tally
        self.clock = clock
        d = config.detector
        #: The pool's keys (detector.pool_prefix; empty: this robot's): its tokens and its
        #: workers' announcements are there.
        self.pool_keys = Keys(d.pool_prefix or config.stack.prefix)
        self.pool = LivePool(
            PoolAudit(camera_rates(config.all_cameras), d.pool_balance, d.pool_alarm_s),
            robot=config.stack.prefix,
            pool_prefix=self.pool_keys.prefix,
            delivery=Delivery(d.pool_deliver_s, d.pool_readmit_s),
            max_robot_cameras=d.max_robot_cameras,
        )
        # The cameras' figures are shown as they are announced (set_cameras), not from config.
        self.agg = Aggregator(
            s.window_s,
            s.history_s,
            on_latency=on_latency,
            max_counters_per_service=s.max_counters_per_service,
            max_classes=s.max_classes,
            pool=self.pool,
        )
        #: The cameras announced now, by name (their figures stay when they are withdrawn).
        self.announced: dict[str, CameraAnnouncement] = {}
        #: The services whose counters are believed: this stack's (camera_<name> and the
        #: detector workers too) and, bounded, any other detector worker: another host's.
        self.known = frozenset(
            (*SERVICES, *config.camera_services.values(), *config.detector_services)
        )
        self.pool_workers = PoolWorkers(s.max_workers)
        self.lock = threading.Lock()

    def set_cameras(self, cameras: Mapping[str, CameraAnnouncement]) -> None:
        """The cameras announced now: each gets its figures; only their detections count."""
        with self.lock:
            self.announced = dict(cameras)
            self.pool.cameras = {name: a.rate_hz for name, a in cameras.items()}
            for camera in cameras:
                self.agg.add_camera(camera)

    def set_workers(self, workers: Mapping[str, Sequence[WorkerAnnouncement]]) -> None:
        """The pool's workers as announced now (every live announcement of each name: their
        capacity and robots): the audit weighs them as the workers do (common/pool_rule.py,
        a name announced twice counting with the lowest capacity, ``one_worker``)."""
        pool = self.pool_keys.prefix
        with self.lock:
            claims = {
                w: [PoolWorker(a.capacity_hz, frozenset(a.prefixes or (pool,))) for a in c]
                for w, c in workers.items()
                if c
            }
            self.pool.announced = {w: one_worker(c) for w, c in claims.items()}
            self.pool.announcements = {w: len(c) for w, c in workers.items()}
        self.audit_pool()

    def on_detections(self, camera: str, key: str, payload: bytes) -> None:
        """``camera``'s detections; ``key``: the one the sample came on (that camera's).
        Those of a camera not announced now are counted and dropped: made-up camera names
        (anyone may put in peer mode) cannot grow the answer."""
        with self.lock:
            announced = camera in self.announced
            if not announced:
                self.agg.count(contract.DETECTIONS_UNANNOUNCED)
        if not announced:
            self.tally.reject(
                contract.DETECTIONS_UNANNOUNCED,
                f"detections of {camera!r:.80}, a camera not announced, ignored",
            )
            return
        max_timing_ms = self.settings.max_timing_ms
        self._take(
            "detections", Detections.decode, key, payload,
            lambda m: self._on_detections(m, camera),
            lambda m, _k: refuse_detections(m, max_timing_ms),
        )  # fmt: skip

    def _on_detections(self, message: Detections, camera: str) -> None:
        """An accepted Detections of ``camera`` (the caller holds ``lock``)."""
        now = self.clock.mono_s()
        self.agg.on_detections(message, now, camera=camera)
        self.pool.saw(camera, now, message.worker)

    def on_pool_member(self, key: str, live: bool) -> None:
        """A detector worker's pool token came (``live``) or went."""
        with self.lock:
            self.pool.member(key.rsplit("/", 1)[-1], live=live)
        self.audit_pool()

    def on_pool_serving(self, key: str, live: bool) -> None:
        """A worker's serving token (common/keys.py::pool_serving) came or went."""
        token = self.pool_keys.pool_serving_parts(key)
        if token is None:
            return
        with self.lock:
            self.pool.serving(token, live=live)
        self.audit_pool()

    def audit_pool(self) -> None:
        """Check the pool's tokens (common/pool_audit.py): a WARNING for what has been wrong
        for ``detector.pool_alarm_s``, a line when it clears; the answer shows what holds."""
        now = self.clock.mono_s()
        with self.lock:
            if not self.pool.heard and not self.pool.cameras:
                return  # no worker ever, no camera announced: nothing to audit
            report = self.pool.check(now)
        for line in lines(report.raised, now):
            self.tally.log.warning("pool: %s", line)
        for finding in report.cleared[:MAX_LINES]:
            self.tally.log.info("pool: no longer so: %s", finding.detail)

    def on_cmd_vel(self, payload: bytes) -> None:
        key = self.tally.keys.cmd_vel()
        self._take(
            "cmd_vel",
            Twist.decode,
            key,
            payload,
            lambda m: self.agg.on_twist(m, self.clock.mono_s()),
        )

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
        self.agg.on_counters(kept, self.clock.mono_s())

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


class MetricsService:
    """The metrics service on ``node``'s bus, at ``node``'s clock: its handlers subscribed to
    every announced camera's detections, cmd_vel and every service's counters, the cameras'
    announcements and the pool's tokens watched, and the metrics query (``keys.metrics()``)
    answered with :meth:`answer`.

    ``run`` calls :meth:`report` every period; an in-process test puts messages, moves its
    fake clock and asks the query itself. :meth:`close` undeclares everything it declared.
    """

    def __init__(
        self, config: Config, node: Node, on_latency: LatencyListener | None = None
    ) -> None:
        self.config = config
        self.node = node
        self.clock = node.clock
        handlers = self.handlers = MetricsHandlers(config, node, on_latency, clock=node.clock)
        keys = node.keys
        # The cameras are the announced ones (common/announce.py): every camera's detections
        # on one subscription, the camera the one its key names; those of a camera not
        # announced are dropped (MetricsHandlers.on_detections).
        self.announced: Announced[CameraAnnouncement] | None = None
        self.announced = announced_cameras(
            node.bus,
            keys,
            self._on_cameras,
            lambda key, exc: node.bad_input(key, exc, topic="camera_announcement"),
        )
        self._on_cameras()  # those already announced (a Zenoh watch reports them as it starts)
        pool = handlers.pool_keys
        self.workers: Announced[WorkerAnnouncement] | None = None
        self.workers = announced_workers(
            node.bus,
            pool,
            self._on_workers,
            lambda key, exc: node.bad_input(key, exc, topic="worker_announcement"),
        )
        self._on_workers()
        self._declared: list[Declared] = [
            node.subscribe_keyed(keys.all_detections(), self._on_detections),
            node.subscribe(keys.cmd_vel(), handlers.on_cmd_vel),
            node.subscribe_keyed(keys.all_counters(), handlers.on_counters),
            node.bus.watch_tokens(pool.all_pool_members(), handlers.on_pool_member),
            node.bus.watch_tokens(pool.all_pool_serving(), handlers.on_pool_serving),
            node.bus.serve(keys.metrics(), lambda _key, _q: strict_json(self.answer()).encode()),
        ]
        self._next_report = self.clock.mono_s() + config.metrics.report_period_s

    def _on_cameras(self) -> None:
        if self.announced is not None:  # else called back while it is being declared
            self.handlers.set_cameras(self.announced.current())

    def _on_workers(self) -> None:
        if self.workers is not None:  # else called back while it is being declared
            self.handlers.set_workers(self.workers.every())

    def _on_detections(self, key: str, payload: bytes) -> None:
        camera = camera_in_key(key)
        if camera is None:  # unreachable: the subscription's keys all name a camera
            self.node.bad_input(key, DecodeError("not a camera's detections key"))
            return
        self.handlers.on_detections(camera, key, payload)

    def answer(self) -> MetricsAnswer:
        """The query's answer: the aggregate at this instant, and the warnings it brings."""
        self.handlers.audit_pool()
        at = self.clock.now()
        to_unix = at.wall_ns / 1e9 - at.mono_ns / 1e9  # the timeline's times in Unix seconds
        with self.handlers.lock:
            out = self.handlers.agg.answer(self.node.header(at), at.mono_ns / 1e9, to_unix)
        out["cameras_announced"] = {
            name: announced_camera(a) for name, a in sorted(self.handlers.announced.items())
        }
        out["warnings"] = advise(self.config, out)
        return out

    def report(self) -> None:
        """Audit the pool's tokens; once a ``report_period_s``, log the figures in a line."""
        self.handlers.audit_pool()
        now = self.clock.mono_s()
        if now < self._next_report:
            return
        self._next_report = now + self.config.metrics.report_period_s
        with self.handlers.lock:
            snap = self.handlers.agg.snapshot(self.node.header(), now)
        self.node.log.info("%s", report_line(snap))

    def close(self) -> None:
        """Undeclare the queryable first, then the watches and the subscriptions."""
        for declared in reversed(self._declared):
            declared.undeclare()
        if self.announced is not None:
            self.announced.close()
        if self.workers is not None:
            self.workers.close()


def announced_camera(a: CameraAnnouncement) -> AnnouncedCamera:
    """A camera's announcement as the metrics answer shows it."""
    return AnnouncedCamera(
        width=a.width, height=a.height, rate_hz=a.rate_hz, mount_yaw_deg=a.mount_yaw_deg,
        hfov_deg=a.hfov_deg, frame_id=a.frame_id, source=a.source, depth=a.depth,
        mount_x_m=a.mount_x_m, mount_y_m=a.mount_y_m, mount_height_m=a.mount_height_m,
    )  # fmt: skip


def run(config: Config, stop: threading.Event) -> int:
    """Serve metrics until ``stop`` is set."""
    s = config.metrics
    exporter = None
    listener: LatencyListener | None = None
    if s.prometheus_port:
        from services.metrics.prometheus import PrometheusExporter  # only when asked for

        exporter = PrometheusExporter()
        listener = exporter.observe
    with ExitStack() as closing:
        node = closing.enter_context(Node("metrics", config))
        service = MetricsService(config, node, listener)
        closing.callback(service.close)
        if exporter is not None:
            closing.callback(exporter.close)  # whatever its start left running
            port = exporter.start(service.answer, s.prometheus_host, s.prometheus_port)
            node.log.info("prometheus metrics on http://%s:%d/metrics", s.prometheus_host, port)
        node.ready()
        while not stop.wait(min(s.report_period_s, config.detector.pool_alarm_s / 2)):
            service.report()
    return 0


def query(config: Config, timeout_s: float) -> MetricsAnswer:
    """Ask the metrics service for its snapshot. Nobody answering within the timeout is a
    StackError naming where it looked and the likely fix (common/reach.py)."""
    session = open_session(config.zenoh, config.principal(OBSERVER))
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


def pool(config: Config) -> dict[str, Any]:
    """The whole detector pool as its tokens say now, asked as ``observer`` from any host (a
    GPU box, which runs no metrics service, included): services/metrics/pool_view.py."""
    bus = ZenohBus(open_session(config.zenoh, config.principal(OBSERVER)))
    try:
        return pool_view(config, bus)
    finally:
        bus.close()
