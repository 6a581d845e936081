"""What every service process has: a Zenoh session, its keys, counters and a health token."""

from __future__ import annotations

import logging
import time
from types import TracebackType
from typing import Self

import zenoh

from common.bus import open_session
from common.counters import Counters
from common.keys import Keys
from common.messages import Header, ServiceCounters, now_ns
from common.settings import Config


class Node:
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
        self.session = open_session(config.zenoh)
        self._token: zenoh.LivelinessToken | None = None
        self._counters_pub = self.session.declare_publisher(self.keys.counters(service))
        self._counters_period_s = counters_period_s
        self._counters_next = 0.0
        self._seq = 0

    def ready(self) -> None:
        """Announce that the service is up and serving."""
        self._token = self.session.liveliness().declare_token(self.keys.health(self.service))
        self.log.info("ready (zenoh id %s)", self.session.info.zid())

    def header(self, stamp_ns: int | None = None, frame_id: str = "") -> Header:
        """A header for a message this service originates, with its own sequence number."""
        self._seq += 1
        return Header(
            stamp_ns=now_ns() if stamp_ns is None else stamp_ns,
            frame_id=frame_id,
            seq=self._seq,
            source=self.service,
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

    def close(self) -> None:
        self.publish_counters(force=True)
        if self._token is not None:
            self._token.undeclare()
        self.session.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
