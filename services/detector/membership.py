"""This worker's place in the detector pool: the bus side of the pool's pure state
(services/detector/pool.py's :class:`PoolView`, common/pool_audit.py's :class:`PoolAudit`),
over the bus protocol (``node.bus``, common/bus.py) and the node's clock (``node.clock``). What
it hears of the pool's announcements is services/detector/pool_hearing.py's, its own tokens
services/detector/pool_tokens.py's."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace
from functools import partial

from common.announce import Announcer
from common.bus import Declared
from common.counters import per_camera
from common.errors import DecodeError
from common.keys import Keys, camera_in_key
from common.messages import Detections, WorkerAnnouncement
from common.node import Node
from common.pool_audit import MAX_LINES, Report, lines
from common.pool_rule import label, one_worker, pool_name
from services.detector import contract
from services.detector.capacity import Capacity
from services.detector.handlers import DetectorHandlers
from services.detector.pool import Change, PoolCamera, PoolView, PoolWorker
from services.detector.pool_checks import PoolChecks, tell_change, tell_drops, tell_refused
from services.detector.pool_depth import PoolDepth
from services.detector.pool_hearing import POOL_ASK_TIMEOUT_S, PoolHearing
from services.detector.pool_stall import Stall, start_watch
from services.detector.pool_tokens import PoolTokens

#: What the service does when this worker comes to serve a camera (its label in counters, and
#: the camera: its robot's prefix and its name there) and when it stops.
OnGained = Callable[[str, PoolCamera], None]
OnLost = Callable[[str], None]


class PoolMember:
    """This worker's place in the detector pool (services/detector/pool.py). The pool lives
    under ``detector.pool_prefix`` (empty: the stack's prefix): this worker's liveliness token
    ``<pool>/detector/pool/<worker id>`` and its announcement ``<pool>/detector/workers/
    <worker id>/<chunk>`` (a WorkerAnnouncement: its capacity, input size, backend, round
    size and the robot prefixes it serves), the others' as they come and go; the cameras
    announced under each robot prefix of ``detector.prefixes`` (empty: the stack's prefix);
    and a frame subscription for each camera it serves, its detections going back on that
    camera's own robot's keys (the service's ``on_gained``), and a depth subscription
    (``<robot>/camera/<cam>/depth``) for each of those whose announcement says ``depth``
    (services/detector/depth_stage.py), dropped when the camera is lost or stops announcing
    depth.

    The bus's threads only note a change; the detection loop calls :meth:`settle` between
    rounds, which recomputes the assignment and declares and undeclares subscriptions there
    (never inside a bus callback). Counted: ``serving`` and ``serving.<cam>`` (1 while
    served; ``<cam>`` is the camera's label, common/pool_rule.py), ``pool_members``,
    ``pool_load_permille`` (the served cameras' share of every heard camera's frame rate),
    ``capacity_hz``, ``pool_strays`` (pool tokens with no announcement, ignored),
    ``capacity_announced``, ``cameras_gained`` and ``cameras_lost`` (and ``.<cam>``:
    hand-overs after the first assignment).

    Its capacity (services/detector/capacity.py) is fed by the loop (:meth:`observe_round`)
    and announced again by :meth:`settle` when it moved enough; the pool then follows it.

    A worker whose loop stalls resigns from the pool until its loop beats again
    (services/detector/pool_stall.py): :meth:`check_stall`, called by a thread of its own
    (:meth:`start_stall_watch`), watches the loop's :meth:`beat`. Counted as
    ``pool_resigned``.

    For each camera it serves, the worker declares a serving token (services/detector/
    pool_tokens.py; withdrawn with its pool token on a stall), and it hears everyone's:
    :meth:`audit` checks them against the membership (common/pool_audit.py) and logs a
    WARNING for what has been wrong for ``detector.pool_alarm_s`` (a member that serves
    nothing, a camera nobody or two serve, a name held twice), and a line when it clears.
    Counted: ``pool_warnings`` (how many hold now).

    A member earns its cameras by delivering, and the pool admits only so many cameras
    (services/detector/pool_checks.py): the worker hears every camera's detections of the
    robots it serves (counted: ``pool_dropped``, ``pool_drops``, ``cameras_refused``).

    Time is the node's clock's (``node.clock.mono_s()``): a test moves it and calls
    :meth:`check_stall` and :meth:`audit` itself.

    **Locks.** Three threads write here: the detection loop (:meth:`beat`, :meth:`settle`,
    :meth:`audit`, :meth:`observe_round`, :meth:`close`), the stall watch
    (:meth:`check_stall`) and the bus's callbacks (a member's, an announcement's or a serving
    token's coming and going). Two locks, always taken in this order when both are:

    - ``_tokens.lock`` covers this worker's own tokens (its pool token and its serving tokens,
      services/detector/pool_tokens.py), and is held over their declaring and undeclaring, so
      that a resignation and a settle's serving tokens never interleave. No bus callback
      takes it.
    - ``_lock`` covers every other attribute written after construction (``_stall``,
      ``_dirty``, ``view``, ``_checks``, ``_subs``, ``_watches``, ``_gauges``,
      ``_handed_over``, ``_strays``) and the handlers' ``serving``. It is never
      held over a bus call: a bus may deliver this worker's own token change to a callback at
      once, in the calling thread, and the callbacks take ``_lock``.

    Subscriptions are declared and undeclared by the loop alone, outside both locks (a slow
    declaration must not keep the stall watch from resigning); only the ``_subs`` dict that
    holds them is written under ``_lock``. The announcer (:class:`common.announce.Announcer`)
    and the capacity are the loop's alone.
    """

    def __init__(
        self,
        node: Node,
        worker_id: str,
        handlers: DetectorHandlers,
        *,
        capacity: Capacity | None = None,
        input_size: int = 0,
        backend: str = "",
        max_batch: int = 1,
        on_gained: OnGained | None = None,
        on_lost: OnLost | None = None,
        stopping: Callable[[], bool] = lambda: False,
    ) -> None:
        config = handlers.config
        s = config.detector
        self.node = node
        self.clock = node.clock
        self.handlers = handlers
        self.zid = node.bus.zid
        self.pool_keys = Keys(s.pool_prefix or config.stack.prefix)
        self.prefixes = s.prefixes or (config.stack.prefix,)
        self.capacity = capacity or Capacity(1.0, s, self.clock.mono_s())
        self._on_gained = on_gained
        self._on_lost = on_lost
        self._closed = threading.Event()
        # The process is asked to stop (its stop event): a worker the watchdog found hung and
        # stopped must never rejoin the pool on its way out (issue 39).
        self._stopping = stopping
        self._told_members = -1  # the pool's size last said in the log
        self._stall_watch: threading.Thread | None = None
        self.announcement = WorkerAnnouncement(
            worker=worker_id,
            capacity_hz=self.capacity.announced,
            input_size=input_size,
            backend=backend,
            max_batch=max_batch,
            prefixes=tuple(self.prefixes),
        )
        self._announcer: Announcer[WorkerAnnouncement] = Announcer(
            node.bus, partial(self.pool_keys.worker_announcement, worker_id)
        )
        self._hearing: PoolHearing | None = None  # from join()
        self._tokens = PoolTokens(node.bus, self.pool_keys, worker_id)
        self._lock = threading.Lock()
        # Under _lock:
        self.view = PoolView(worker_id, self._mine(), s.pool_balance)
        self._stall = Stall(s.pool_stall_s, self.clock.mono_s())
        self._dirty = True
        self._subs: dict[str, Declared] = {}
        self._depth = PoolDepth(node, handlers)  # the loop's (services/detector/pool_depth.py)
        self._watches: list[Declared] = []
        self._gauges: dict[str, int] = {}
        self._handed_over = False
        self._checks = PoolChecks(s)  # services/detector/pool_checks.py
        self._strays: list[str] = []
        self._told_refused: dict[str, str] = {}  # the loop's: those it has logged
        with self._lock:
            for cam in handlers.frame_keys:
                self._gauge(per_camera(contract.SERVING, cam), 0)
            for name in contract.POOL_GAUGES:
                self._gauge(name, 0)
            self._gauge(contract.CAPACITY_HZ, round(self.capacity.announced))
        for name in (
            contract.CAMERAS_GAINED,
            contract.CAMERAS_LOST,
            contract.POOL_RESIGNED,
            contract.CAPACITY_ANNOUNCED,
            contract.POOL_DROPS,
        ):
            node.counters.add(name, 0)

    def _mine(self) -> PoolWorker:
        return PoolWorker(self.announcement.capacity_hz, frozenset(self.prefixes))

    @property
    def resigned(self) -> bool:
        """Whether the worker has left the pool for a stall (until its next :meth:`beat`)."""
        with self._lock:
            return self._stall.resigned

    def join(self) -> None:
        """Learn who is in the pool, announce this worker, declare its token and take its
        cameras. A worker of this name already there is a StackError (one line, exit 1:
        services/detector/pool_tokens.py's ``members_if_free``)."""
        keys, bus = self.pool_keys, self.node.bus
        members = self._tokens.members_if_free(POOL_ASK_TIMEOUT_S)
        # The announcement before the token: a token alone is no member (a stray).
        self._announcer.update(self.announcement)
        with self._tokens.lock:
            self._tokens.declare_member()
        self._hearing = PoolHearing(bus, keys, self.prefixes, self._changed, self._bad)
        self._hearing.catch_up()
        watches = [bus.watch_tokens(keys.all_pool_members(), self._on_member)]
        for key in members:
            self._member(key, joined=True)
        watches.append(bus.watch_tokens(keys.all_pool_serving(), self._on_serving))
        # Every camera's detections, whoever puts them: a camera is served when they arrive,
        # by the worker they name (common/pool_delivery.py).
        for prefix in self.prefixes:
            on_detections = partial(self._on_detections, prefix)
            watches.append(self.node.subscribe_keyed(Keys(prefix).all_detections(), on_detections))
        with self._lock:
            self._watches.extend(watches)
        self.settle()
        with self._lock:
            self._stall.last_beat = self.clock.mono_s()

    def _changed(self) -> None:
        with self._lock:
            self._dirty = True

    def _bad(self, key: str, error: Exception) -> None:
        self.node.bad_input(key, error)

    def observe_round(self, frames: int, seconds: float) -> None:
        """A busy round of the loop: ``frames`` detected in ``seconds`` (the capacity's
        moving average; announced again by :meth:`settle` when it moved enough)."""
        self.capacity.observe(frames, seconds)

    def start_stall_watch(self, wait: Callable[[float], bool] | None = None) -> threading.Thread:
        """Call :meth:`check_stall` a few times per ``detector.pool_stall_s`` on a thread of
        its own, until :meth:`close` (or until ``wait(period)``, the pause between checks,
        returns True: by default the close's event)."""
        pause = self._closed.wait if wait is None else wait
        self._stall_watch = start_watch(self.check_stall, self._stall.stall_s, pause)
        return self._stall_watch

    def beat(self) -> None:
        """The detection loop passed (call it on every pass, before :meth:`settle`). After a
        stall that made this worker resign, declare its token again: the pool gives its share
        back, and the next settle() serves it again."""
        with self._tokens.lock:
            with self._lock:
                # Asked to stop (the watchdog's SIGTERM and SIGCONT to a worker frozen for
                # too long): it stays out of the pool until it exits.
                may_return = not self._closed.is_set() and not self._stopping()
                back = self._stall.beat(self.clock.mono_s(), may_return)
                if back:
                    self._dirty = True
            if back:
                self._tokens.declare_member()
        if back:
            self.node.log.warning("the detection loop runs again: back in the pool")

    def check_stall(self) -> bool:
        """Resign when the loop has not beaten for ``detector.pool_stall_s`` and others are in
        the pool: withdraw the pool token and the serving tokens, refuse frames. True when it
        resigned now."""
        with self._tokens.lock:
            with self._lock:
                # Alone, there is nobody to hand to.
                others = not self._closed.is_set() and len(self.view.members) > 1
                stalled = self._stall.resign(others, self.clock.mono_s, self._stopping)
                if stalled:
                    # The frames that come meanwhile are not ours: restored by the settle()
                    # after the next beat(), never before (beat clears the flag).
                    self.handlers.serving = frozenset()
            if stalled:
                self._tokens.resign()
        if stalled:
            self.node.counters.add(contract.POOL_RESIGNED)
            self.node.log.warning(
                "the detection loop has not passed for %.1f s (detector.pool_stall_s): "
                "leaving the pool so that the other workers take its cameras",
                self._stall.stall_s,
            )
        return stalled

    def _on_detections(self, prefix: str, key: str, payload: bytes) -> None:
        camera = camera_in_key(key)
        if camera is None:
            return
        try:
            worker = Detections.decode(payload).worker
        except (DecodeError, ValueError) as exc:
            self.node.bad_input(key, exc)
            return
        name = pool_name(prefix, camera, self.pool_keys.prefix)
        with self._lock:
            if name in self.view.cameras:  # a made-up name grows nothing
                self._checks.delivery.saw(name, self.clock.mono_s(), worker)

    def _on_serving(self, key: str, alive: bool) -> None:
        parts = self.pool_keys.pool_serving_parts(key)
        if parts is None:
            return
        with self._lock:
            self._checks.serving(parts, alive=alive)

    def audit(self) -> Report | None:
        """Check the pool's tokens (at most every :data:`AUDIT_PERIOD_S`): log what became
        wrong, and what stopped being so; None when it is not yet time."""
        now = self.clock.mono_s()
        with self._lock:
            if not self._checks.audit_due(now):
                return None
        mine = self._tokens.serving()
        with self._lock:
            report = self._checks.check(now, self.view, mine)
            self._gauge(contract.POOL_WARNINGS, len(report.current))
        for line in lines(report.raised, now):
            self.node.log.warning("pool: %s", line)
        for finding in report.cleared[:MAX_LINES]:
            self.node.log.info("pool: no longer so: %s", finding.detail)
        return report

    def _on_member(self, key: str, alive: bool) -> None:
        self._member(key, joined=alive)

    def _member(self, key: str, *, joined: bool) -> None:
        worker = key.rsplit("/", 1)[-1]
        with self._lock:
            if joined:
                self.view.joined(worker)
            else:
                self.view.left(worker)
                if worker != self.view.me:
                    self._checks.delivery.left(worker)
            self._dirty = True

    def settle(self) -> None:
        """Announce a capacity that moved enough; apply a change of the pool (members,
        announcements, cameras), if any, to this worker's subscriptions and counters; drop
        the members that deliver nothing, take back those whose time is over."""
        self._announce_capacity()
        self._judge_delivery()
        with self._lock:
            if not self._dirty:
                return
            self._dirty = False
            self._read_announcements()
            strays = self.view.strays()
            fresh = [w for w in strays if w not in self._strays]
            self._strays = strays
            self._gauge(contract.POOL_STRAYS, len(strays))
            change = self.view.settle()
            self._checks.delivery.note(self.clock.mono_s(), self.view.owners, self.view.cameras)
            refused = dict(self._checks.refused)
            if refused.keys() != self._told_refused.keys():
                self._gauge(contract.CAMERAS_REFUSED, len(refused))
        tell_refused(self.node, refused, self._told_refused)
        self._told_refused = refused
        if fresh:
            self.node.log.warning(
                "pool token(s) with no worker announcement ignored (no member): %s",
                ", ".join(fresh[:MAX_LINES]),
            )
        self._apply(change)

    def _judge_delivery(self) -> None:
        """Who delivers (common/pool_delivery.py): a member none of whose cameras of a robot
        has had a detection for ``detector.pool_deliver_s`` is dropped from that robot's
        assignment; one whose time is over is given cameras again."""
        with self._lock:
            before = self.view.excluded
            dropped, readmitted = self._checks.judge(self.clock.mono_s(), self.view)
            if self.view.excluded != before:
                self._dirty = True
                self._gauge(contract.POOL_DROPPED, len(self.view.excluded))
        tell_drops(self.node, dropped, readmitted, self._checks.delivery.deliver_s)

    def _announce_capacity(self) -> None:
        capacity = self.capacity.due(self.clock.mono_s())
        if capacity is None:
            return
        self.announcement = replace(
            self.announcement, capacity_hz=capacity, seq=self.announcement.seq + 1
        )
        self._announcer.update(self.announcement)
        self.node.counters.add(contract.CAPACITY_ANNOUNCED)
        self.node.log.info("capacity now %.1f frames/s: announced", capacity)
        with self._lock:
            self.view.mine = self._mine()
            self._gauge(contract.CAPACITY_HZ, round(capacity))
            self._dirty = True

    def _read_announcements(self) -> None:
        """The view's workers and cameras from the announcements heard (the caller holds
        _lock; the listeners take only their own)."""
        hearing = self._hearing
        if hearing is not None:
            # A name announced by two sessions counts as the lowest capacity claimed, its
            # own included (common/pool_rule.py's one_worker): everyone counts it alike.
            every = hearing.workers()
            me = self.view.me
            self.view.announced = {w: one_worker(c) for w, c in every.items() if w != me}
            self.view.mine = one_worker([self._mine(), *every.get(me, ())])
            self.view.announcements = {w: len(c) for w, c in every.items()}
        announced, depth = hearing.cameras() if hearing is not None else ({}, {})
        self._checks.admit(self.view, announced)
        self._depth.keys = depth

    def _apply(self, change: Change) -> None:
        node, handlers = self.node, self.handlers
        gained = [label(cam) for cam in change.gained]
        lost = [label(cam) for cam in change.lost]
        serving = frozenset(label(cam) for cam in change.serving)
        with self._lock:
            dropped = [self._subs.pop(cam) for cam in lost if cam in self._subs]
        for sub in dropped:
            sub.undeclare()
        if self._on_lost is not None:
            for name in lost:
                self._on_lost(name)
        for name, cam in zip(gained, change.gained, strict=True):
            where = change.cameras[cam]
            handlers.add_camera(name, Keys(where.prefix).frame(where.camera))
            if self._on_gained is not None:
                self._on_gained(name, where)
        with self._lock:
            # Under the lock the stall watch resigns under: a change computed before a
            # resignation (this pass stalled inside it) never switches serving back on; the
            # settle() after the next beat() serves the share again.
            handlers.serve(
                frozenset() if self._stall.resigned else serving, tuple(gained), tuple(lost)
            )
        # Bounded: no queue of stale frames ahead of the slot, which keeps the newest only.
        added = {
            cam: node.subscribe_bounded(handlers.frame_keys[cam], partial(handlers.on_frame, cam))
            for cam in gained
        }
        with self._lock:
            self._subs.update(added)
            for cam in (*gained, *lost):
                self._gauge(per_camera(contract.SERVING, cam), int(cam in serving))
            handed_over = self._handed_over  # the first assignment, at start, is no hand-over
            self._handed_over = True
            self._gauge(contract.SERVING, len(serving))
            self._gauge(contract.POOL_MEMBERS, change.members)
            self._gauge(contract.POOL_LOAD_PERMILLE, round(change.load * 1000))
        self._tokens.sync_serving(change.serving)
        self._depth.sync(change.serving)
        tell_change(node, change, gained, lost, handed_over, self._told_members)
        self._told_members = change.members

    def _gauge(self, name: str, value: int) -> None:
        """Set gauge ``name`` to ``value`` (the caller holds _lock). Counters only add: a
        gauge moves by its difference."""
        self.node.counters.add(name, value - self._gauges.get(name, 0))
        self._gauges[name] = value

    def close(self) -> None:
        self._closed.set()
        if self._stall_watch is not None:
            self._stall_watch.join()
        with self._lock:
            declared = [*self._subs.values(), *self._watches]
            self._subs.clear()
            self._watches.clear()
        self._depth.close()
        for d in declared:
            d.undeclare()
        if self._hearing is not None:
            self._hearing.close()
        self._tokens.close()
        self._announcer.close()  # after the token: a token alone is ignored, never a member
