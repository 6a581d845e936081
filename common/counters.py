"""Thread-safe named counters that a service publishes as ServiceCounters."""

from __future__ import annotations

import threading
from collections import Counter


class Counters:
    """Monotonic counts such as ``frames_in``, ``dropped`` or ``bad_input``.

    Zenoh callbacks run on Zenoh's threads while the service loop runs on its own, hence the
    lock; increments are rare enough (per message) that it is never contended for long.
    """

    def __init__(self, *names: str) -> None:
        self._lock = threading.Lock()
        self._counts: Counter[str] = Counter({n: 0 for n in names})

    def add(self, name: str, n: int = 1) -> None:
        with self._lock:
            self._counts[name] += n

    def get(self, name: str) -> int:
        with self._lock:
            return self._counts[name]

    def snapshot(self) -> dict[str, int]:
        with self._lock:
            return dict(self._counts)


def per_camera(name: str, camera: str) -> str:
    """The name of counter ``name`` for one camera: ``frames_in.rear`` (a service that serves
    several cameras keeps its totals under the plain names and each camera's under these)."""
    return f"{name}.{camera}"
