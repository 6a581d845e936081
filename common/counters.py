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

# -- inputs judged for freshness (common/freshness.py), each counted by its fate ------------------
IN = "in"  # fresh, and the newest held
LATE = "late"  # fresh, but older than the one held
#: The freshness verdicts an input is dropped for (common/freshness.py ``Verdict`` but fresh;
#: named here so that a contract loads no messages: a unit test checks they agree).
DROP_VERDICTS = ("stale", "future", "replay")
OUTCOMES = (IN, LATE, *DROP_VERDICTS)


def input_counter(stream: str, outcome: str) -> str:
    """The counter of ``stream``'s messages (``detections``, ``depth`` ...) with ``outcome``
    (IN, LATE or a freshness verdict): ``detections_stale``."""
    return f"{stream}_{outcome}"


def input_counters(stream: str) -> frozenset[str]:
    """Every fate's counter of ``stream`` (:data:`OUTCOMES`)."""
    return frozenset(input_counter(stream, o) for o in OUTCOMES)


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
