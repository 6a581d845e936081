"""The bus protocol (common/bus.py) in one process: the in-process tests' bus.

A :class:`MemoryHub` is the bus; each :meth:`MemoryHub.join` is one participant (a service, a
test's probe), a :class:`MemoryBus`. By default delivery happens in the putting thread, before
``put`` returns, in the order subscribers were declared: a test puts a message and reads what
came of it on the next line, with no wait. With ``threads`` (``MemoryHub(threads=2, seed=7)``)
it happens on threads of the hub's own, as on Zenoh: each subscription's and each token
watch's calls in order, the declarations interleaved in an order shuffled by ``seed``
(common/memory_delivery.py); a test then calls ``hub.drain()`` before it reads what came of a
put. A participant's ``close()`` is its process ending: its tokens go, and every watcher hears
it.

Access control as the supervisor's router enforces it: a hub made with the router's
``access_control`` section (stack/access.py) takes each participant's principal
(``hub.join(name, principal=...)``) and denies by default what the section does not allow on
ingress (common/acl.py): a denied put reaches nobody, a denied subscription hears nothing, a
denied token is not seen, a denied queryable answers nothing, a denied query or token watch
hears nothing. Each denial is noted in ``hub.denied`` as ``(principal, kind, key)``; as on the
router, the participant is not told.

What it leaves out of Zenoh on purpose: no network (nothing is lost, and one publisher's
samples are never reordered), a bounded subscription's depth (every sample is handled), and a
queryable's answer runs in the querier's thread. Those are the real-process tests' to check. A
handler's exception is not swallowed as Zenoh's thread would (it logs it): it reaches the test
that put the sample (or, delivered on the hub's threads, its next ``drain()``).
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import Any

from common.acl import AccessRules
from common.bus import Answer, OnSample, OnToken, QoS, Reply, Sample
from common.memory_delivery import DRAIN_TIMEOUT_S, Delivery, Inline, Threaded


def intersects(a: str, b: str) -> bool:
    """Whether key expressions ``a`` and ``b`` have a key in common (``*``: one chunk, ``**``:
    any number of chunks, none included)."""
    return _meet(tuple(a.split("/")), tuple(b.split("/")))


def _meet(a: tuple[str, ...], b: tuple[str, ...]) -> bool:
    if not a and not b:
        return True
    if a and a[0] == "**":
        return _meet(a[1:], b) or (bool(b) and _meet(a, b[1:]))
    if b and b[0] == "**":
        return _meet(a, b[1:]) or (bool(a) and _meet(a[1:], b))
    if not a or not b:
        return False
    if a[0] == b[0] or a[0] == "*" or b[0] == "*":
        return _meet(a[1:], b[1:])
    return False


@dataclass(eq=False)
class _Entry:
    """One declaration: whose, on which key, and what it calls."""

    owner: MemoryBus
    key: str
    call: Callable[..., object] | None = None
    alive: bool = field(default=True)

    def undeclare(self) -> None:
        self.owner.hub._undeclare(self)


def _call(entry: _Entry, *args: object) -> None:
    """``entry``'s callback with ``args``, unless it was undeclared meanwhile."""
    if entry.alive and entry.call is not None:
        entry.call(*args)


class MemoryPublisher:
    def __init__(
        self,
        bus: MemoryBus,
        key: str,
        qos: QoS,
        max_payload_bytes: int | None,
        on_refused: Callable[[str, int], None] | None,
    ) -> None:
        self.key = key
        self.qos = qos
        self._bus = bus
        self._max = max_payload_bytes
        self._on_refused = on_refused
        self._source = f"{bus.zid}/{next(bus.hub._ids)}"
        self.sent = 0

    def put(self, payload: bytes) -> bool:
        if self._max is not None and len(payload) > self._max:
            if self._on_refused is not None:
                self._on_refused(self.key, len(payload))
            return False
        self.sent += 1
        if self._bus.admitted("put", self.key):  # else the router drops it, unsaid
            self._bus.hub._deliver(Sample(self.key, bytes(payload), self._source))
        return True

    def undeclare(self) -> None:
        return None


class MemoryHub:
    """The in-process bus: every participant's subscriptions, tokens and queryables; with
    ``access`` (the router's ``access_control`` section), its access rules too. ``threads``:
    deliver on that many threads of the hub's own (0: in the putting thread), the order of
    the declarations shuffled by ``seed``; :meth:`close` ends them."""

    def __init__(
        self,
        access: Mapping[str, Any] | None = None,
        names: Callable[[str], str] | None = None,
        *,
        threads: int = 0,
        seed: int | None = None,
    ) -> None:
        self.rules = AccessRules(access) if access else None
        #: The name each participant's principal authenticates as (a role's, as
        #: ``Config.principal`` names it: ``<prefix>/<role>``); None: as given.
        self.names = names
        #: What the rules denied: ``(principal, kind, key expression)``, in order.
        self.denied: list[tuple[str, str, str]] = []
        self._lock = threading.RLock()
        self._subs: list[_Entry] = []
        self._tokens: list[_Entry] = []
        self._watches: list[_Entry] = []
        self._queryables: list[_Entry] = []
        self._ids = itertools.count(1)
        self._buses = itertools.count(1)
        self._delivery: Delivery = Threaded(threads, seed) if threads else Inline()

    def drain(self, timeout_s: float = DRAIN_TIMEOUT_S) -> None:
        """Return once every sample put and every token's event so far (and what their
        handlers put in turn) has been handled: at once when delivery is in the putting
        thread. A handler's exception since the last drain is raised here."""
        self._delivery.drain(timeout_s)

    def close(self) -> None:
        """End the delivery threads (nothing more is delivered)."""
        self._delivery.close()

    def join(self, name: str = "", *, principal: str | None = None) -> MemoryBus:
        """A new participant (``name`` only for reading its id in a failure), authenticated
        as ``principal`` (through the hub's ``names``: a role, qualified as its robot's): a
        hub with access rules needs one, as the router admits no anonymous link."""
        if self.rules is not None and principal is None:
            raise ValueError("a hub with access rules needs each participant's principal")
        zid = f"mem{next(self._buses)}{'-' + name if name else ''}"
        return MemoryBus(self, zid, principal)

    def _admit(self, principal: str | None, kind: str, key: str) -> bool:
        if self.rules is None:
            return True
        assert principal is not None  # join() asks for one
        name = self.names(principal) if self.names else principal
        if self.rules.allows(name, kind, key):
            return True
        with self._lock:
            self.denied.append((principal, kind, key))
        return False

    def tokens(self, key: str = "**") -> list[str]:
        """The keys of the live tokens that ``key`` matches, sorted."""
        with self._lock:
            return sorted(t.key for t in self._tokens if intersects(key, t.key))

    def _add(self, where: list[_Entry], entry: _Entry) -> _Entry:
        with self._lock:
            where.append(entry)
        return entry

    def _deliver(self, sample: Sample) -> None:
        with self._lock:
            subs = [s for s in self._subs if intersects(s.key, sample.key)]
        for sub in subs:
            self._delivery.submit(sub, partial(_call, sub, sample))

    def _token_event(self, key: str, alive: bool) -> None:
        with self._lock:
            watches = [w for w in self._watches if intersects(w.key, key)]
        for watch in watches:
            self._delivery.submit(watch, partial(_call, watch, key, alive))

    def _history(self, watch: _Entry, keys: list[str]) -> None:
        """A new watch hears the tokens alive now first, as its first calls."""
        for key in keys:
            self._delivery.submit(watch, partial(_call, watch, key, True))

    def _undeclare(self, entry: _Entry) -> None:
        with self._lock:
            if not entry.alive:
                return
            entry.alive = False
            for where in (self._subs, self._tokens, self._watches, self._queryables):
                if entry in where:
                    where.remove(entry)
                    break
            token = entry.call is None
        if token:
            self._token_event(entry.key, False)

    def _close(self, bus: MemoryBus) -> None:
        with self._lock:
            mine = [
                e
                for where in (self._subs, self._watches, self._queryables, self._tokens)
                for e in where
                if e.owner is bus
            ]
        for entry in mine:
            self._undeclare(entry)


class MemoryBus:
    """One participant of a :class:`MemoryHub`: the bus protocol (common/bus.py)."""

    def __init__(self, hub: MemoryHub, zid: str, principal: str | None = None) -> None:
        self.hub = hub
        self.principal = principal
        self._zid = zid
        self.closed = False

    def admitted(self, kind: str, key: str) -> bool:
        """Whether the hub's access rules let this participant send ``kind`` on ``key``."""
        return self.hub._admit(self.principal, kind, key)

    def _denied(self, key: str) -> _Entry:
        """A declaration the router refused: registered nowhere, so it never hears a thing."""
        return _Entry(self, key, alive=False)

    @property
    def zid(self) -> str:
        return self._zid

    def publisher(
        self,
        key: str,
        qos: QoS,
        *,
        max_payload_bytes: int | None = None,
        on_refused: Callable[[str, int], None] | None = None,
    ) -> MemoryPublisher:
        return MemoryPublisher(self, key, qos, max_payload_bytes, on_refused)

    def subscribe(self, key: str, handle: OnSample) -> _Entry:
        if not self.admitted("declare_subscriber", key):
            return self._denied(key)
        return self.hub._add(self.hub._subs, _Entry(self, key, handle))

    def subscribe_bounded(self, key: str, handle: OnSample, depth: int) -> _Entry:
        return self.subscribe(key, handle)

    def declare_token(self, key: str) -> _Entry:
        if not self.admitted("liveliness_token", key):
            return self._denied(key)
        entry = self.hub._add(self.hub._tokens, _Entry(self, key))
        self.hub._token_event(key, True)
        return entry

    def watch_tokens(self, key: str, handle: OnToken) -> _Entry:
        if not self.admitted("declare_liveliness_subscriber", key):
            return self._denied(key)
        entry = _Entry(self, key, handle)
        with self.hub._lock:  # no token comes or goes between its history and its watch
            history = self.hub.tokens(key)
            self.hub._add(self.hub._watches, entry)
        self.hub._history(entry, history)
        return entry

    def live_tokens(self, key: str, timeout_s: float) -> list[str]:
        if not self.admitted("liveliness_query", key):
            return []
        return self.hub.tokens(key)

    def serve(self, key: str, answer: Answer) -> _Entry:
        if not self.admitted("declare_queryable", key):
            return self._denied(key)
        return self.hub._add(self.hub._queryables, _Entry(self, key, answer))

    def query(self, key: str, timeout_s: float, payload: bytes = b"") -> list[Reply]:
        if not self.admitted("query", key):
            return []
        with self.hub._lock:
            queryables = [q for q in self.hub._queryables if intersects(q.key, key)]
        out = []
        for q in queryables:
            assert q.call is not None
            answer = q.call(key, payload)
            if isinstance(answer, bytes) and q.owner.admitted("reply", q.key):
                out.append(Reply(q.key, answer))
        return out

    def linked(self, timeout_s: float = 0.0) -> bool:
        """Always: the hub links every participant, as a router would."""
        return True

    def close(self) -> None:
        self.closed = True
        self.hub._close(self)
