"""This worker's place in the detector pool: the bus side of the pool's pure state
(services/detector/pool.py's :class:`PoolView`, common/pool_audit.py's :class:`PoolAudit`),
over the bus protocol (``node.bus``, common/bus.py) and the node's clock (``node.clock``)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace
from functools import partial
from typing import Any

from common.announce import Announced, Announcer, announced_cameras, announced_workers
from common.bus import Declared
from common.counters import per_camera
from common.errors import StackError
from common.keys import Keys, camera_in_key
from common.messages import CameraAnnouncement, WorkerAnnouncement
from common.node import Node
from common.pool_audit import MAX_LINES, Report, lines
from common.pool_rule import label, one_worker, pool_name
from services.detector import contract
from services.detector.capacity import Capacity
from services.detector.counting import count_for
from services.detector.handlers import DetectorHandlers
from services.detector.pool import Change, PoolCamera, PoolView, PoolWorker
from services.detector.pool_checks import PoolChecks, tell_drops, tell_refused
from services.detector.pool_depth import PoolDepth

#: How long a joining worker asks who is already in the pool before it takes its cameras: the
#: query ends as soon as every peer answered; this bounds it on a slow link.
POOL_ASK_TIMEOUT_S = 1.0
#: The stall watch looks this many times per ``detector.pool_stall_s`` (and at most every
#: :data:`STALL_CHECK_MIN_S`): a stall is noticed within a quarter of the limit after it.
STALL_CHECKS = 4
STALL_CHECK_MIN_S = 0.05
CATCH_UP_CHECKS = 20  # how often a joining worker looks whether it heard every announcement

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

    A worker whose loop stalls (an inference that never returns, a deadlock) while the bus's
    threads still keep its token alive would hold its cameras until the watchdog restarts it.
    So :meth:`check_stall` (called by a thread of its own, :meth:`start_stall_watch`, a few
    times per ``detector.pool_stall_s``) watches the loop's :meth:`beat`: none for
    ``detector.pool_stall_s`` while other workers are in the pool and the worker **resigns**,
    withdrawing its pool token (the others take its cameras at once) and refusing frames; its
    next beat declares the token again and it takes its share back. A worker alone in the pool
    stays: nobody could take over. Counted as ``pool_resigned``.

    For each camera it serves, the worker declares a serving token ``<pool>/detector/serving/
    <worker>/<zenoh id>/<camera>`` (withdrawn with its pool token on a stall), and it hears
    everyone's: :meth:`audit` checks them against the membership (common/pool_audit.py) and
    logs a WARNING for what has been wrong for ``detector.pool_alarm_s`` (a member that serves
    nothing, a camera nobody or two serve, a name held twice), and a line when it clears.
    Counted: ``pool_warnings`` (how many hold now).

    A member earns its cameras by delivering (services/detector/pool_checks.py,
    common/pool_delivery.py): the worker hears every camera's detections of the robots it
    serves and drops from a robot's assignment a member none of whose cameras of it has had a
    detection for ``detector.pool_deliver_s`` (counted: ``pool_dropped``, ``pool_drops``).
    Announced cameras over ``detector.max_robot_cameras`` of a robot, or whose counter label
    another's has, are refused (``cameras_refused``).

    Time is the node's clock's (``node.clock.mono_s()``): a test moves it and calls
    :meth:`check_stall` and :meth:`audit` itself.

    **Locks.** Three threads write here: the detection loop (:meth:`beat`, :meth:`settle`,
    :meth:`audit`, :meth:`observe_round`, :meth:`close`), the stall watch
    (:meth:`check_stall`) and the bus's callbacks (a member's, an announcement's or a serving
    token's coming and going). Two locks, always taken in this order when both are:

    - ``_token_lock`` covers this worker's own tokens: ``_token`` (its pool token) and
      ``_serving_tokens``, and is held over their declaring and undeclaring, so that a
      resignation and a settle's serving tokens never interleave. No bus callback takes it.
    - ``_lock`` covers every other attribute written after construction (``_last_beat``,
      ``_resigned``, ``_dirty``, ``view``, ``_checks``, ``_subs``, ``_watches``,
      ``_gauges``, ``_handed_over``, ``_strays``) and the handlers' ``serving``. It is never
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
        self._stall_s = s.pool_stall_s
        self._closed = threading.Event()
        # The process is asked to stop (its stop event): a worker the watchdog found hung and
        # stopped must never rejoin the pool on its way out (issue 39).
        self._stopping = stopping
        self._told_members = -1  # the pool's size last said in the log
        self._heard = threading.Event()  # an announcement came or went
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
        self._workers: Announced[WorkerAnnouncement] | None = None
        self._cameras: dict[str, Announced[CameraAnnouncement]] = {}
        self._token_lock = threading.Lock()
        self._lock = threading.Lock()
        # Under _token_lock:
        self._token: Declared | None = None
        self._serving_tokens: dict[str, Declared] = {}
        # Under _lock:
        self.view = PoolView(worker_id, self._mine(), s.pool_balance)
        self._last_beat = self.clock.mono_s()
        self._resigned = False
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
            return self._resigned

    def join(self) -> None:
        """Learn who is in the pool, announce this worker, declare its token and take its
        cameras. A worker of this name already there (its pool token or its announcement
        alive) is a StackError (one line, exit 1): two processes of one name would each serve
        every camera the rule gives the name. (One the query misses, two started at once, is
        the audit's ``name_twice`` warning.) The supervisor tries again after its backoff: a
        process just killed takes its tokens with its links."""
        keys, bus, me = self.pool_keys, self.node.bus, self.view.me
        members = bus.live_tokens(keys.all_pool_members(), POOL_ASK_TIMEOUT_S)
        mine = keys.pool_member(me)
        held = [mine] if mine in members else []
        held += bus.live_tokens(keys.worker_announcements_of(me), POOL_ASK_TIMEOUT_S)
        if held:
            raise StackError(
                f"a detector worker named {me!r} is already in the pool ({held[0][:120]}): "
                "not starting a second; give each host its own detector.worker_id"
            )
        # The announcement before the token: a token alone is no member (a stray).
        self._announcer.update(self.announcement)
        with self._token_lock:
            self._token = bus.declare_token(mine)
        self._workers = announced_workers(bus, keys, self._changed, self._bad)
        for prefix in self.prefixes:
            robot = Keys(prefix)
            self._cameras[prefix] = announced_cameras(bus, robot, self._changed, self._bad)
        self._catch_up()
        watches = [bus.watch_tokens(keys.all_pool_members(), self._on_member)]
        for key in members:
            self._member(key, joined=True)
        watches.append(bus.watch_tokens(keys.all_pool_serving(), self._on_serving))
        # Every camera's detections, whoever puts them: a camera is served when they arrive
        # (common/pool_delivery.py). Not decoded: their arrival is all that is noted.
        for prefix in self.prefixes:
            on_detections = partial(self._on_detections, prefix)
            watches.append(self.node.subscribe_keyed(Keys(prefix).all_detections(), on_detections))
        with self._lock:
            self._watches.extend(watches)
        self.settle()
        with self._lock:
            self._last_beat = self.clock.mono_s()

    def _catch_up(self) -> None:
        """Wait (at most :data:`POOL_ASK_TIMEOUT_S`) until the listeners hold every
        announcement alive on the bus now, so that the first assignment is the pool's, not
        that of a worker that believes itself alone (which would serve every camera for a
        moment). On an in-process bus they are there at once."""
        bus = self.node.bus
        expected: list[tuple[Announced[Any], set[str]]] = []
        if self._workers is not None:
            keys = bus.live_tokens(self.pool_keys.all_worker_announcements(), POOL_ASK_TIMEOUT_S)
            expected.append((self._workers, _names(keys, self.pool_keys.worker_announcement_parts)))
        for prefix, heard in self._cameras.items():
            robot = Keys(prefix)
            keys = bus.live_tokens(robot.all_camera_announcements(), POOL_ASK_TIMEOUT_S)
            expected.append((heard, _names(keys, robot.camera_announcement_parts)))
        for _ in range(CATCH_UP_CHECKS):
            if all(names <= heard.current().keys() for heard, names in expected):
                return
            self._heard.wait(POOL_ASK_TIMEOUT_S / CATCH_UP_CHECKS)
            self._heard.clear()

    def _changed(self) -> None:
        self._heard.set()
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
        period = max(STALL_CHECK_MIN_S, self._stall_s / STALL_CHECKS)
        pause = self._closed.wait if wait is None else wait

        def watch() -> None:
            while not pause(period):
                self.check_stall()

        self._stall_watch = threading.Thread(target=watch, name="pool-stall-watch", daemon=True)
        self._stall_watch.start()
        return self._stall_watch

    def beat(self) -> None:
        """The detection loop passed (call it on every pass, before :meth:`settle`). After a
        stall that made this worker resign, declare its token again: the pool gives its share
        back, and the next settle() serves it again."""
        with self._token_lock:
            with self._lock:
                self._last_beat = self.clock.mono_s()
                # Asked to stop (the watchdog's SIGTERM and SIGCONT to a worker frozen for
                # too long): it stays out of the pool until it exits.
                back = self._resigned and not self._closed.is_set() and not self._stopping()
                if back:
                    self._resigned = False
                    self._dirty = True
            if back:
                keys = self.pool_keys
                self._token = self.node.bus.declare_token(keys.pool_member(self.view.me))
        if back:
            self.node.log.warning("the detection loop runs again: back in the pool")

    def check_stall(self) -> bool:
        """Resign when the loop has not beaten for ``detector.pool_stall_s`` and others are in
        the pool: withdraw the pool token and the serving tokens, refuse frames. True when it
        resigned now."""
        with self._token_lock:
            with self._lock:
                stalled = (
                    not self._resigned
                    and not self._closed.is_set()
                    and len(self.view.members) > 1  # alone, there is nobody to hand to
                    and (
                        self.clock.mono_s() - self._last_beat > self._stall_s
                        or self._stopping()  # on its way out: hand over now, not at close()
                    )
                )
                if stalled:
                    self._resigned = True
                    # The frames that come meanwhile are not ours: restored by the settle()
                    # after the next beat(), never before (beat clears the flag).
                    self.handlers.serving = frozenset()
            if stalled:
                if self._token is not None:
                    self._token.undeclare()
                    self._token = None
                self._withdraw_serving()
        if stalled:
            self.node.counters.add(contract.POOL_RESIGNED)
            self.node.log.warning(
                "the detection loop has not passed for %.1f s (detector.pool_stall_s): "
                "leaving the pool so that the other workers take its cameras",
                self._stall_s,
            )
        return stalled

    def _on_detections(self, prefix: str, key: str, _payload: bytes) -> None:
        camera = camera_in_key(key)
        if camera is None:
            return
        name = pool_name(prefix, camera, self.pool_keys.prefix)
        with self._lock:
            if name in self.view.cameras:  # a made-up name grows nothing
                self._checks.delivery.saw(name, self.clock.mono_s())

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
        with self._token_lock:
            mine = {(self.view.me, self.zid, cam) for cam in self._serving_tokens}
        with self._lock:
            report = self._checks.check(now, self.view, mine)
            self._gauge(contract.POOL_WARNINGS, len(report.current))
        for line in lines(report.raised, now):
            self.node.log.warning("pool: %s", line)
        for finding in report.cleared[:MAX_LINES]:
            self.node.log.info("pool: no longer so: %s", finding.detail)
        return report

    def _withdraw_serving(self) -> None:
        """Undeclare every serving token (the caller holds _token_lock)."""
        for token in self._serving_tokens.values():
            token.undeclare()
        self._serving_tokens.clear()

    def _sync_serving(self, serving: frozenset[str]) -> None:
        """One serving token for each camera of ``serving``, and none for another."""
        keys, bus = self.pool_keys, self.node.bus
        with self._token_lock:
            if self._token is None:
                return  # resigned or closed: it serves nothing until it is back
            for cam in [c for c in self._serving_tokens if c not in serving]:
                self._serving_tokens.pop(cam).undeclare()
            for cam in sorted(serving - self._serving_tokens.keys()):
                key = keys.pool_serving(self.view.me, self.zid, cam)
                self._serving_tokens[cam] = bus.declare_token(key)

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
        pool = self.pool_keys.prefix
        if self._workers is not None:
            # A name announced by two sessions counts as the lowest capacity claimed, its
            # own included (common/pool_rule.py's one_worker): everyone counts it alike.
            every = {
                w: [PoolWorker(a.capacity_hz, frozenset(a.prefixes or (pool,))) for a in heard]
                for w, heard in self._workers.every().items()
            }
            me = self.view.me
            self.view.announced = {w: one_worker(c) for w, c in every.items() if w != me}
            self.view.mine = one_worker([self._mine(), *every.get(me, ())])
            self.view.announcements = {w: len(c) for w, c in every.items()}
        heard = [
            (prefix, cam, a)
            for prefix, announced in self._cameras.items()
            for cam, a in announced.current().items()
        ]
        announced = {
            pool_name(prefix, cam, pool): PoolCamera(prefix, cam, a.rate_hz)
            for prefix, cam, a in heard
        }
        self._checks.admit(self.view, announced)
        self._depth.keys = {
            pool_name(prefix, cam, pool): Keys(prefix).depth(cam)
            for prefix, cam, a in heard
            if a.depth
        }

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
            handlers.serve(frozenset() if self._resigned else serving, tuple(gained), tuple(lost))
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
        self._sync_serving(change.serving)
        self._depth.sync(change.serving)
        if handed_over:
            for cam in gained:
                count_for(node, cam, contract.CAMERAS_GAINED)
            for cam in lost:
                count_for(node, cam, contract.CAMERAS_LOST)
        told, self._told_members = self._told_members, change.members
        if change.gained or change.lost or change.members != told:
            node.log.info(
                "pool of %d: serving %s (gained %s, lost %s)",
                change.members,
                sorted(change.serving) or "no camera",
                list(change.gained),
                list(change.lost),
            )

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
        for heard in self._cameras.values():
            heard.close()
        if self._workers is not None:
            self._workers.close()
        with self._token_lock:
            self._withdraw_serving()
            if self._token is not None:
                self._token.undeclare()
                self._token = None
        self._announcer.close()  # after the token: a token alone is ignored, never a member


def _names(keys: list[str], parse: Callable[[str], tuple[str, str] | None]) -> set[str]:
    """The announcers' names of announcement ``keys`` (common/keys.py's ``*_parts``)."""
    return {parts[0] for parts in map(parse, keys) if parts is not None}
