"""What every service process has: a bus (common/bus.py), its keys, counters and a health token.

``Tally`` is the part without the bus: the counters and the rate-limited log that a handler
reports bad and refused input to. A service's handlers take a Tally, so that a test builds one
and calls a handler directly; ``Node`` is a Tally with a bus and a clock.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Protocol, TypeVar

from common.bus import Bus, Declared, Publisher, QoS
from common.clock import BOOT_ID, SYSTEM_CLOCK, Clock, Stamp
from common.counters import BAD_INPUT, PAYLOAD_TOO_LARGE, Counters
from common.errors import DecodeError
from common.keys import Keys
from common.lifecycle import Closing
from common.messages import Header, ServiceCounters
from common.ratelimit import LogLimiter
from common.settings import StackSettings, ZenohSettings

_M = TypeVar("_M")


class NodeConfig(Protocol):
    """What a node reads of the stack's config (stack/config.py's ``Config`` has it): the key
    prefix and how to join the bus."""

    @property
    def stack(self) -> StackSettings: ...

    @property
    def zenoh(self) -> ZenohSettings: ...

    def principal(self, role: str) -> str: ...


#: Samples that may wait for a bounded subscription's handler (``Node.subscribe_bounded``):
#: one waits while one is handled, so that the handler never waits on the bus for the next.
BOUNDED_DEPTH = 1


# What a bad-input counter may add to "bad_input.": 80 characters in all, the longest name the
# metrics service believes (services/metrics/trust.py).
MAX_WHERE_CHARS = 80 - len(f"{BAD_INPUT}.")


#: What a handler publishes through: a declared publisher's ``put``, or a list's ``append``.
Put = Callable[[bytes], object]


class Tally:
    """A service's counters and its log of dropped input: what its handlers report to. No bus."""

    def __init__(self, service: str, config: NodeConfig) -> None:
        self.service = service
        self.config = config
        self.keys = Keys(config.stack.prefix)
        self.counters = Counters()
        self.log = logging.getLogger(service)
        self.log_limit = LogLimiter()  # bad input's log lines, per key (common/ratelimit.py)

    def decode(self, key: str, decode: Callable[[bytes], _M], payload: bytes) -> _M | None:
        """``decode(payload)``; None for garbage, counted as bad input on ``key`` and dropped
        (never raised into Zenoh's thread)."""
        try:
            return decode(payload)
        except DecodeError as exc:
            self.bad_input(key, exc)
            return None

    def bad_input(self, key: str, error: Exception, *, topic: str = "") -> None:
        """Log (rate-limited per key), count and drop one bad message.

        It is counted as ``bad_input`` and ``bad_input.<where>``: ``topic`` when given (the
        ROS 2 bridge names the ROS topic: its keys end in a 64-hex type hash), else the key's
        last chunk; cut to ``MAX_WHERE_CHARS`` so that the name always fits the metrics
        service's limit.
        """
        self.counters.add(BAD_INPUT)
        where = topic.strip("/").replace("/", ".") if topic else key.rsplit("/", 1)[-1]
        self.counters.add(f"{BAD_INPUT}.{where[:MAX_WHERE_CHARS]}")
        self._log_limited(key, BAD_INPUT, "dropped bad input on %s: %s", key, error)

    def reject(self, counter: str, message: str, *, key: str = "") -> None:
        """Count one message that was fine as bytes but unfit to act on (stale, replayed,
        oversize ...). Always counted; logged in full only for the first few per ``key``
        (default: the counter), then summarised once a period (common/ratelimit.py), so that
        a flood cannot fill the log while the count stays exact."""
        self.counters.add(counter)
        self._log_limited(key or counter, counter, "%s (%s)", message, counter)

    def warn(self, reason: str, message: str, *, key: str = "") -> None:
        """Log ``message`` as a WARNING, limited as :meth:`reject`'s lines are (per ``key``,
        default ``reason``), counting nothing: a judgement (a second stream on a key ...) whose
        count, if any, the caller keeps."""
        self._log_limited(key or reason, reason, "%s (%s)", message, reason)

    def _log_limited(self, key: str, reason: str, fmt: str, *args: object) -> None:
        # Per key and counter: a flood of garbage cannot hide the first bombs on the same key.
        admit = self.log_limit.admit(reason if key == reason else f"{key} ({reason})", reason)
        if admit.summary:
            self.log.warning("%s", admit.summary)
        if admit.log:
            self.log.warning(fmt, *args)


class Node(Tally, Closing):
    """A service's presence on the bus (common/bus.py): a Zenoh session's, unless a ``bus`` is
    given (an in-process test's, common/memory_bus.py), and its clock (the system's unless a
    ``clock`` is given). Closing the node closes the bus.

    ``ready()`` declares the liveliness token ``<prefix>/health/<service>``; the supervisor and
    tests wait on it instead of sleeping. ``publish_counters()`` is rate-limited, so the service
    loop may call it every iteration.
    """

    def __init__(
        self,
        service: str,
        config: NodeConfig,
        *,
        counters_period_s: float = 1.0,
        bus: Bus | None = None,
        clock: Clock = SYSTEM_CLOCK,
    ) -> None:
        super().__init__(service, config)
        if bus is None:
            from common.zenoh_bus import ZenohBus, open_session

            bus = ZenohBus(open_session(config.zenoh, config.principal(service)), self.log)
        self.bus = bus
        self.clock = clock
        self._token: Declared | None = None
        self._counters_pub = self.publisher(self.keys.counters(service), QoS.TELEMETRY)
        self._counters_period_s = counters_period_s
        self._counters_next = 0.0
        self._seq: dict[str, int] = {}  # per frame_id: one numbering per stream

    def ready(self) -> None:
        """Announce that the service is up and serving."""
        self._token = self.bus.declare_token(self.keys.health(self.service))
        self.log.info("ready (zenoh id %s)", self.bus.zid)

    def publisher(self, key: str, qos: QoS) -> Publisher:
        """Declare a publisher with the QoS profile of its role (common/bus.py). A payload
        over ``zenoh.max_payload_bytes`` is not sent but counted (``payload_too_large``)."""
        return self.bus.publisher(
            key,
            qos,
            max_payload_bytes=self.config.zenoh.max_payload_bytes,
            on_refused=self._payload_refused,
        )

    def _payload_refused(self, key: str, size: int) -> None:
        limit = self.config.zenoh.max_payload_bytes
        self.reject(
            PAYLOAD_TOO_LARGE,
            f"{size}-byte payload on {key} not sent: over zenoh.max_payload_bytes ({limit}), "
            "which Zenoh would lose",
            key=key,
        )

    def subscribe(self, key: str, handle: Callable[[bytes], None]) -> Declared:
        """Subscribe to ``key``: ``handle`` gets each sample's payload (and decodes it itself,
        through ``Tally.decode``)."""
        return self.bus.subscribe(key, lambda sample: handle(sample.payload))

    def subscribe_bounded(
        self, key: str, handle: Callable[[bytes], None], depth: int = BOUNDED_DEPTH
    ) -> Declared:
        """Subscribe to ``key`` with at most ``depth`` samples waiting for ``handle``, which
        runs on a thread of the subscription's own (common/zenoh_bus.py, ``Bounded``). For
        large samples that may come faster than they are handled: camera frames."""
        return self.bus.subscribe_bounded(key, lambda sample: handle(sample.payload), depth)

    def subscribe_keyed(self, key: str, handle: Callable[[str, bytes], None]) -> Declared:
        """Subscribe to ``key`` (a wildcard, say): ``handle(key, payload)`` gets the key each
        sample came on with its payload."""
        return self.bus.subscribe(key, lambda sample: handle(sample.key, sample.payload))

    def header(self, stamp: Stamp | None = None, frame_id: str = "") -> Header:
        """A header for a message this service originates, stamped on both clocks (now, unless
        ``stamp`` is given), with its own sequence number: one numbering per ``frame_id``, so
        that a receiver of one stream (the simulator's frames, not its scans) sees no gaps."""
        seq = self._seq[frame_id] = self._seq.get(frame_id, 0) + 1
        at = self.clock.now() if stamp is None else stamp
        return Header(
            stamp_ns=at.wall_ns,
            frame_id=frame_id,
            seq=seq,
            source=self.service,
            mono_ns=at.mono_ns,
            boot_id=BOOT_ID,
        )

    def publish_counters(self, *, force: bool = False) -> None:
        now = self.clock.mono_s()
        if not force and now < self._counters_next:
            return
        self._counters_next = now + self._counters_period_s
        for line in self.log_limit.due():  # the summaries of floods that stopped
            self.log.warning("%s", line)
        msg = ServiceCounters(
            header=self.header(), service=self.service, counters=self.counters.snapshot()
        )
        self._counters_pub.put(msg.encode())

    def close(self) -> None:
        for line in self.log_limit.drain():
            self.log.warning("%s", line)
        self.publish_counters(force=True)
        if self._token is not None:
            self._token.undeclare()
        self.bus.close()
