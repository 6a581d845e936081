"""Thread-safe named counters that a service publishes as ServiceCounters.

Each service declares its counter names as constants in its contract
(``services/<name>/contract.py``); the names every service counts are here.
"""

from __future__ import annotations

import threading
from collections import Counter

#: Bad input (garbage on the bus), in all and as ``bad_input.<where>`` (common/node.py).
BAD_INPUT = "bad_input"
#: A payload over ``zenoh.max_payload_bytes``, not sent (common/node.py).
PAYLOAD_TOO_LARGE = "payload_too_large"
#: What every service may count, whatever it is.
COMMON = frozenset({BAD_INPUT, PAYLOAD_TOO_LARGE})


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


def split_per_camera(name: str) -> tuple[str, str]:
    """``(name, camera)`` of a per-camera counter name (:func:`per_camera`), ``(name, "")``
    for a plain one."""
    base, _, camera = name.rpartition(".")
    return (base, camera) if base else (name, "")
