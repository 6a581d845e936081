"""What every service process has: a Zenoh session, its keys, counters and a health token."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import TypeVar

import zenoh

from common.bus import Publisher, QoS, open_session
from common.clock import BOOT_ID, Stamp, now
from common.counters import Counters
from common.errors import DecodeError
from common.keys import Keys
from common.lifecycle import Closing
from common.messages import Header, ServiceCounters
from common.settings import Config

_M = TypeVar("_M")


class Node(Closing):
    """A service's presence on the bus.

    ``ready()`` declares the liveliness token ``<prefix>/health/<service>``; the supervisor and
    tests wait on it instead of sleeping. ``publish_counters()`` is rate-limited, so the service
    loop may call it every iteration.
    """

    def __init__(self, service: str, config: Config, *, counters_period_s: float = 1.0) -> None:
        self.service = service
        self.config = config
        self.keys = Keys(config.stack.prefix)
        self.counters = Counters()
        self.log = logging.getLogger(service)
        self.session = open_session(config.zenoh, service)
        self._token: zenoh.LivelinessToken | None = None
        self._counters_pub = self.publisher(self.keys.counters(service), QoS.TELEMETRY)
        self._counters_period_s = counters_period_s
        self._counters_next = 0.0
        self._seq = 0

    def ready(self) -> None:
        """Announce that the service is up and serving."""
        self._token = self.session.liveliness().declare_token(self.keys.health(self.service))
        self.log.info("ready (zenoh id %s)", self.session.info.zid())

    def publisher(self, key: str, qos: QoS) -> Publisher:
        """Declare a publisher with the QoS profile of its role (common/bus.py)."""
        return Publisher(self.session, key, qos)

    def subscribe(
        self, key: str, decode: Callable[[bytes], _M], handle: Callable[[_M, zenoh.Sample], None]
    ) -> zenoh.Subscriber[None]:
        """Subscribe to ``key``: each sample is decoded, garbage is counted as bad input and
        dropped (never raised into Zenoh's thread), and the message goes to ``handle``."""

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                msg = decode(sample.payload.to_bytes())
            except DecodeError as exc:
                self.bad_input(key, exc)
                return
            handle(msg, sample)

        return self.session.declare_subscriber(key, on_sample)

    def header(self, stamp: Stamp | None = None, frame_id: str = "") -> Header:
        """A header for a message this service originates, stamped on both clocks (now, unless
        ``stamp`` is given), with its own sequence number."""
        self._seq += 1
        at = now() if stamp is None else stamp
        return Header(
            stamp_ns=at.wall_ns,
            frame_id=frame_id,
            seq=self._seq,
            source=self.service,
            mono_ns=at.mono_ns,
            boot_id=BOOT_ID,
        )

    def publish_counters(self, *, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now < self._counters_next:
            return
        self._counters_next = now + self._counters_period_s
        msg = ServiceCounters(
            header=self.header(), service=self.service, counters=self.counters.snapshot()
        )
        self._counters_pub.put(msg.encode())

    def bad_input(self, key: str, error: Exception) -> None:
        """Log, count and drop one bad message."""
        self.counters.add("bad_input")
        self.counters.add(f"bad_input.{key.rsplit('/', 1)[-1]}")
        self.log.warning("dropped bad input on %s: %s", key, error)

    def reject(self, counter: str, message: str) -> None:
        """Count one message that was fine as bytes but unfit to act on (stale, replayed, from
        a foreign source ...). Logged at the 1st, 2nd, 4th, 8th ... and every 1024th, so that a
        flood cannot fill the log while the count stays exact."""
        self.counters.add(counter)
        n = self.counters.get(counter)
        if n & (n - 1) == 0 or n % 1024 == 0:
            self.log.warning("%s (%s: %d so far)", message, counter, n)

    def close(self) -> None:
        self.publish_counters(force=True)
        if self._token is not None:
            self._token.undeclare()
        self.session.close()
