"""This worker's place in the detector pool: the bus side of the pool's pure state
(services/detector/pool.py's :class:`PoolView`, common/pool_audit.py's :class:`PoolAudit`),
over the bus protocol (``node.bus``, common/bus.py) and the node's clock (``node.clock``)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from functools import partial

from common.bus import Declared
from common.counters import per_camera
from common.errors import StackError
from common.node import Node
from common.pool_audit import MAX_LINES, PoolAudit, Report, Serving, lines
from services.detector import contract
from services.detector.handlers import DetectorHandlers, count_for
from services.detector.pool import Change, PoolView, camera_weights

#: How long a joining worker asks who is already in the pool before it takes its cameras: the
#: query ends as soon as every peer answered; this bounds it on a slow link.
POOL_ASK_TIMEOUT_S = 1.0
AUDIT_PERIOD_S = 0.5  # how often the loop audits the pool's tokens (common/pool_audit.py)
#: The stall watch looks this many times per ``detector.pool_stall_s`` (and at most every
#: :data:`STALL_CHECK_MIN_S`): a stall is noticed within a quarter of the limit after it.
STALL_CHECKS = 4
STALL_CHECK_MIN_S = 0.05


class PoolMember:
    """This worker's place in the detector pool (services/detector/pool.py): its liveliness
    token ``<prefix>/detector/pool/<worker id>``, the others' tokens as they come and go, and a
    frame subscription for each camera it serves.

    The bus's threads only note a join or a leave; the detection loop calls :meth:`settle`
    between rounds, which recomputes the assignment and declares and undeclares subscriptions
    there (never inside a bus callback). Counted: ``serving`` and ``serving.<cam>`` (1 while
    served), ``pool_members``, ``pool_load_permille`` (the served cameras' share of every
    camera's pixel rate), ``cameras_gained`` and ``cameras_lost`` (and ``.<cam>``: hand-overs
    after the first assignment).

    A worker whose loop stalls (an inference that never returns, a deadlock) while the bus's
    threads still keep its token alive would hold its cameras until the watchdog restarts it.
    So :meth:`check_stall` (called by a thread of its own, :meth:`start_stall_watch`, a few
    times per ``detector.pool_stall_s``) watches the loop's :meth:`beat`: none for
    ``detector.pool_stall_s`` while other workers are in the pool and the worker **resigns**,
    withdrawing its pool token (the others take its cameras at once) and refusing frames; its
    next beat declares the token again and it takes its share back. A worker alone in the pool
    stays: nobody could take over. Counted as ``pool_resigned``.

    For each camera it serves, the worker declares a serving token ``<prefix>/detector/serving/
    <worker>/<zenoh id>/<camera>`` (withdrawn with its pool token on a stall), and it hears
    everyone's: :meth:`audit` checks them against the membership (common/pool_audit.py) and
    logs a WARNING for what has been wrong for ``detector.pool_alarm_s`` (a member that serves
    nothing, a camera nobody or two serve, a name held twice), and a line when it clears.
    Counted: ``pool_warnings`` (how many hold now).

    Time is the node's clock's (``node.clock.mono_s()``): a test moves it and calls
    :meth:`check_stall` and :meth:`audit` itself.

    **Locks.** Three threads write here: the detection loop (:meth:`beat`, :meth:`settle`,
    :meth:`audit`, :meth:`close`), the stall watch (:meth:`check_stall`) and the bus's
    callbacks (a member's or a serving token's coming and going). Two locks, always taken in
    this order when both are:

    - ``_token_lock`` covers this worker's own tokens: ``_token`` (its pool token) and
      ``_serving_tokens``, and is held over their declaring and undeclaring, so that a
      resignation and a settle's serving tokens never interleave. No bus callback takes it.
    - ``_lock`` covers every other attribute written after construction (``_last_beat``,
      ``_resigned``, ``_dirty``, ``view``, ``_servers``, ``_subs``, ``_watches``, ``_gauges``,
      ``_handed_over``, ``_audit``, ``_audit_next``) and the handlers' ``serving``. It is never
      held over a bus call: a bus may deliver this worker's own token change to a callback at
      once, in the calling thread, and the callbacks take ``_lock``.

    Subscriptions are declared and undeclared by the loop alone, outside both locks (a slow
    declaration must not keep the stall watch from resigning); only the ``_subs`` dict that
    holds them is written under ``_lock``.
    """

    def __init__(self, node: Node, worker_id: str, handlers: DetectorHandlers) -> None:
        config = handlers.config
        self.node = node
        self.clock = node.clock
        self.handlers = handlers
        self.zid = node.bus.zid
        self._stall_s = config.detector.pool_stall_s
        self._closed = threading.Event()
        self._stall_watch: threading.Thread | None = None
        self._token_lock = threading.Lock()
        self._lock = threading.Lock()
        # Under _token_lock:
        self._token: Declared | None = None
        self._serving_tokens: dict[str, Declared] = {}
        # Under _lock:
        self.view = PoolView(
            worker_id, camera_weights(config.all_cameras), config.detector.pool_balance
        )
        self._last_beat = self.clock.mono_s()
        self._resigned = False
        self._dirty = True
        self._subs: dict[str, Declared] = {}
        self._watches: list[Declared] = []
        self._gauges: dict[str, int] = {}
        self._handed_over = False
        self._servers: set[Serving] = set()  # everyone's serving tokens, as heard
        self._audit = PoolAudit(self.view.weights, self.view.balance, config.detector.pool_alarm_s)
        self._audit_next = 0.0
        with self._lock:
            for cam in handlers.frame_keys:
                self._gauge(per_camera(contract.SERVING, cam), 0)
            for name in contract.POOL_GAUGES:
                self._gauge(name, 0)
        for name in (contract.CAMERAS_GAINED, contract.CAMERAS_LOST, contract.POOL_RESIGNED):
            node.counters.add(name, 0)

    @property
    def resigned(self) -> bool:
        """Whether the worker has left the pool for a stall (until its next :meth:`beat`)."""
        with self._lock:
            return self._resigned

    def join(self) -> None:
        """Learn who is in the pool, declare this worker's token and take its cameras. A worker
        of this name already there is a StackError (one line, exit 1): two processes of one
        name would each serve every camera the rule gives the name. (One the query misses, two
        started at once, is the audit's ``name_twice`` warning.) The supervisor tries again
        after its backoff: a process just killed takes its token with its links."""
        keys, bus = self.node.keys, self.node.bus
        members = bus.live_tokens(keys.all_pool_members(), POOL_ASK_TIMEOUT_S)
        mine = keys.pool_member(self.view.me)
        if mine in members:
            raise StackError(
                f"a detector worker named {self.view.me!r} is already in the pool ({mine}): "
                "not starting a second; give each host its own detector.worker_id"
            )
        with self._token_lock:
            self._token = bus.declare_token(mine)
        watches = [bus.watch_tokens(keys.all_pool_members(), self._on_member)]
        for key in members:
            self._member(key, joined=True)
        watches.append(bus.watch_tokens(keys.all_pool_serving(), self._on_serving))
        with self._lock:
            self._watches.extend(watches)
        self.settle()
        with self._lock:
            self._last_beat = self.clock.mono_s()

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
                back = self._resigned and not self._closed.is_set()
                self._resigned = False
                if back:
                    self._dirty = True
            if back:
                keys = self.node.keys
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
                    and self.clock.mono_s() - self._last_beat > self._stall_s
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

    def _on_serving(self, key: str, alive: bool) -> None:
        parts = self.node.keys.pool_serving_parts(key)
        if parts is None:
            return
        with self._lock:
            if alive:
                self._servers.add(parts)
            else:
                self._servers.discard(parts)

    def audit(self) -> Report | None:
        """Check the pool's tokens (at most every :data:`AUDIT_PERIOD_S`): log what became
        wrong, and what stopped being so; None when it is not yet time."""
        now = self.clock.mono_s()
        with self._lock:
            if now < self._audit_next:
                return None
            self._audit_next = now + AUDIT_PERIOD_S
        with self._token_lock:
            mine = {(self.view.me, self.zid, cam) for cam in self._serving_tokens}
        with self._lock:
            report = self._audit.check(now, set(self.view.members), self._servers | mine)
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
        keys, bus = self.node.keys, self.node.bus
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
            self._dirty = True

    def settle(self) -> None:
        """Apply a membership change, if any, to this worker's subscriptions and counters."""
        with self._lock:
            if not self._dirty:
                return
            self._dirty = False
            change = self.view.settle()
        self._apply(change)

    def _apply(self, change: Change) -> None:
        node, handlers = self.node, self.handlers
        with self._lock:
            dropped = [self._subs.pop(cam) for cam in change.lost if cam in self._subs]
        for sub in dropped:
            sub.undeclare()
        with self._lock:
            # Under the lock the stall watch resigns under: a change computed before a
            # resignation (this pass stalled inside it) never switches serving back on; the
            # settle() after the next beat() serves the share again.
            handlers.serve(
                frozenset() if self._resigned else change.serving, change.gained, change.lost
            )
        # Bounded: no queue of stale frames ahead of the slot, which keeps the newest only.
        added = {
            cam: node.subscribe_bounded(handlers.frame_keys[cam], partial(handlers.on_frame, cam))
            for cam in change.gained
        }
        with self._lock:
            self._subs.update(added)
            for cam in (*change.gained, *change.lost):
                self._gauge(per_camera(contract.SERVING, cam), int(cam in change.serving))
            handed_over = self._handed_over  # the first assignment, at start, is no hand-over
            self._handed_over = True
            self._gauge(contract.SERVING, len(change.serving))
            self._gauge(contract.POOL_MEMBERS, change.members)
            self._gauge(contract.POOL_LOAD_PERMILLE, round(change.load * 1000))
        self._sync_serving(change.serving)
        if handed_over:
            for cam in change.gained:
                count_for(node, cam, contract.CAMERAS_GAINED)
            for cam in change.lost:
                count_for(node, cam, contract.CAMERAS_LOST)
        if change.gained or change.lost:
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
        for d in declared:
            d.undeclare()
        with self._token_lock:
            self._withdraw_serving()
            if self._token is not None:
                self._token.undeclare()
                self._token = None
