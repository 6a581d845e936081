"""What a service does on the bus, as a protocol: publish, subscribe, liveliness tokens and
their watch, queryables and queries. Pure: no Zenoh here.

Two implementations: :class:`common.zenoh_bus.ZenohBus` over a Zenoh session (what the
processes run), and :class:`common.memory_bus.MemoryBus`, every participant in one process
with delivery in the caller's thread (what the in-process tests run, with a fake clock:
deterministic and instant) or on threads of the hub's own (to see races). A service's wiring
takes a ``Bus``; nothing above it knows which.

Key expressions are Zenoh's: chunks split by ``/``, ``*`` matching one chunk and ``**`` any
number of them (common/keys.py builds every one).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from enum import Enum
from typing import Protocol


class QoS(Enum):
    """Publisher profiles by role: (priority, drop under congestion, express). The priority
    is Zenoh's name for it; common/zenoh_bus.py maps it.

    Control and safety messages (cmd_vel, e-stop) go first, express, on the real-time queue;
    sensor data goes last, so that a flood of frames can never hold back a stop. Every role
    drops under congestion, control too (docs/security.md, "QoS by role")."""

    CONTROL = ("REAL_TIME", True, True)
    PERCEPTION = ("DATA_HIGH", True, True)
    SENSOR = ("DATA", True, False)
    TELEMETRY = ("DATA_LOW", True, False)


@dataclass(frozen=True, slots=True)
class Sample:
    """One message as a subscriber gets it: the key it came on, its bytes, and who put it
    (its publisher's global id, or "unidentified")."""

    key: str
    payload: bytes
    source: str = "unidentified"


@dataclass(frozen=True, slots=True)
class Reply:
    """One answer to a query: the key it answers on and its bytes."""

    key: str
    payload: bytes


class Declared(Protocol):
    """Something declared on the bus (a subscription, a token, a queryable, a publisher)."""

    def undeclare(self) -> None: ...


def undeclare_all(declared: Iterable[Declared]) -> None:
    """Undeclare each of ``declared``, in order (a start-up's ExitStack callback)."""
    for d in declared:
        d.undeclare()


class Publisher(Declared, Protocol):
    key: str

    def put(self, payload: bytes) -> bool:
        """Send ``payload``; False when it was refused (over the payload limit)."""
        ...


#: A subscriber's callback, and a liveliness watch's: (token key, alive).
OnSample = Callable[[Sample], None]
OnToken = Callable[[str, bool], None]
#: A queryable's answer for a query on ``key`` with ``payload``: the bytes to reply, or None.
Answer = Callable[[str, bytes], bytes | None]


class Bus(Protocol):
    """One participant's view of the bus (a Zenoh session, or a member of a MemoryHub)."""

    @property
    def zid(self) -> str:
        """This participant's id on the bus (the Zenoh session id)."""
        ...

    def publisher(
        self,
        key: str,
        qos: QoS,
        *,
        max_payload_bytes: int | None = None,
        on_refused: Callable[[str, int], None] | None = None,
    ) -> Publisher:
        """Declare a publisher on ``key`` with the QoS of its role. A payload over
        ``max_payload_bytes`` is not sent: ``on_refused(key, size)`` is told."""
        ...

    def subscribe(self, key: str, handle: OnSample) -> Declared:
        """Every sample on ``key`` (a key expression) to ``handle``."""
        ...

    def subscribe_bounded(self, key: str, handle: OnSample, depth: int) -> Declared:
        """As :meth:`subscribe`, with at most ``depth`` samples waiting for ``handle`` (which
        runs on a thread of the subscription's own on Zenoh): for large samples that may come
        faster than they are handled."""
        ...

    def declare_token(self, key: str) -> Declared:
        """A liveliness token on ``key``: alive until undeclared or this participant is gone."""
        ...

    def watch_tokens(self, key: str, handle: OnToken) -> Declared:
        """``handle(token key, alive)`` for every token on ``key`` that appears or goes; the
        ones alive now first."""
        ...

    def live_tokens(self, key: str, timeout_s: float) -> list[str]:
        """The keys of the tokens alive on ``key`` now (waiting at most ``timeout_s``)."""
        ...

    def serve(self, key: str, answer: Answer) -> Declared:
        """A queryable on ``key``: a query's reply is ``answer(query key, payload)``."""
        ...

    def query(self, key: str, timeout_s: float, payload: bytes = b"") -> list[Reply]:
        """Ask ``key``; every reply that came within ``timeout_s``."""
        ...

    def linked(self, timeout_s: float = 0.0) -> bool:
        """Whether this participant reaches anyone (a router or a peer is linked to it),
        waiting up to ``timeout_s`` for a first link: a client that heard nothing says
        whether it reached no stack or a stack that said nothing (common/reach.py)."""
        ...

    def close(self) -> None:
        """Leave the bus: every declaration of this participant is gone."""
        ...
