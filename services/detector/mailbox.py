"""A one-slot mailbox: the newest item wins, and every overwritten one is counted as dropped.

The detector is often slower than the camera. Queueing frames would make every detection
later than the last; keeping only the newest keeps latency bounded, and counting the drops
keeps them visible.
"""

from __future__ import annotations

import threading
from typing import Generic, TypeVar

from common.clock import wall_ns

_T = TypeVar("_T")


class Mailbox(Generic[_T]):
    """Holds at most one item, with its arrival time (``common.clock.wall_ns()``)."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._payload: _T | None = None
        self._received_ns = 0

    def put(self, payload: _T) -> bool:
        """Store ``payload``; True when it replaced one nobody took (a dropped item)."""
        with self._cond:
            dropped = self._payload is not None
            self._payload = payload
            self._received_ns = wall_ns()
            self._cond.notify()
        return dropped

    def take(self, timeout: float) -> tuple[_T, int] | None:
        """The newest item and when it arrived, or None after ``timeout`` seconds."""
        with self._cond:
            if self._payload is None and not self._cond.wait_for(
                lambda: self._payload is not None, timeout
            ):
                return None
            payload, self._payload = self._payload, None
            assert payload is not None
            return payload, self._received_ns
