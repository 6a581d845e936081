"""What the metrics service believes, and how its answer stays JSON. Pure: no bus, no clock.

Anyone on the bus can put on ``counters/<name>`` and on the detections keys (in the default
peer mode nothing checks who). So the service believes counters only from a known service (its
config's, or a detector worker of the pool on any host, a bounded number of those:
:class:`PoolWorkers`), on that service's own key, naming itself, in bounded numbers and with
counts >= 0; and a detector's stage times only when finite and within a bound. The rest is
refused and counted (``metrics.refused.<why>``). Under the secure profile the router lets only
a service's own principal put on its counters key (stack/access_table.py), so a key that names a
service also names who sent it: see docs/security.md.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections import Counter
from collections.abc import Iterable, Mapping
from typing import Any

from common.messages import Detections, ServiceCounters
from common.settings import is_detector_service

#: The longest counter name believed (the stack's own are under 40 characters).
MAX_NAME_CHARS = 80


class PoolWorkers:
    """The detector workers not in this stack's config whose counters are believed: a pool's
    workers on other hosts (``detector_<worker_id>`` ...), which no config lists. The first
    ``max_workers`` names heard are admitted for good; a further one is refused
    (``too_many_workers``), so that made-up names cannot grow the metrics without bound.
    Not thread-safe: the caller holds its lock."""

    def __init__(self, max_workers: int) -> None:
        self.max_workers = max_workers
        self.names: set[str] = set()

    def admit(self, service: str) -> str | None:
        """None if ``service``'s counters may be believed (admitting it if there is room), else
        why not."""
        if service in self.names:
            return None
        if len(self.names) >= self.max_workers:
            return "too_many_workers"
        self.names.add(service)
        return None


def refuse_counters(
    msg: ServiceCounters,
    key: str,
    known: Iterable[str],
    max_names: int,
    workers: PoolWorkers | None = None,
) -> str | None:
    """Why ``msg``, heard on ``key`` (``.../counters/<service>``), is not believed at all; None
    if it is. Reasons: ``unknown_service``, ``service_mismatch``, ``too_many_names``,
    ``too_many_workers``. A service not in ``known`` may still be a detector worker of another
    host, admitted by ``workers`` once the message is otherwise sound. A bad name or count
    spoils only itself (:func:`split_counters`), never the service's others."""
    service = key.rsplit("/", 1)[-1]
    other_worker = service not in known and workers is not None and is_detector_service(service)
    if service not in known and not other_worker:
        return "unknown_service"
    if msg.service != service:
        return "service_mismatch"
    if len(msg.counters) > max_names:
        return "too_many_names"
    if other_worker:
        assert workers is not None
        return workers.admit(service)
    return None


def split_counters(msg: ServiceCounters) -> tuple[ServiceCounters, Counter[str]]:
    """``msg`` with only the counters that can be believed, and how many were left out, by
    reason: ``bad_name`` (empty or over MAX_NAME_CHARS), ``negative_count``. One refused name
    once froze every counter of the ROS 2 bridge: now it costs only itself."""
    kept: dict[str, int] = {}
    refused: Counter[str] = Counter()
    for name, value in msg.counters.items():
        if not 0 < len(name) <= MAX_NAME_CHARS:
            refused["bad_name"] += 1
        elif value < 0:
            refused["negative_count"] += 1
        else:
            kept[name] = value
    if not refused:
        return msg, refused
    return dataclasses.replace(msg, counters=kept), refused


def refuse_detections(msg: Detections, max_timing_ms: float) -> str | None:
    """Why ``msg``'s figures are not believed (``bad_timing``: a stage time outside
    0..``max_timing_ms``); None if they are. Non-finite times never decode at all."""
    if any(not 0.0 <= ms <= max_timing_ms for ms in msg.timing_ms.values()):
        return "bad_timing"
    return None


def finite(value: Any) -> Any:
    """``value`` with every float that is NaN or infinite replaced by None (JSON null),
    through dicts, lists and tuples."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    return value


def strict_json(value: Any) -> str:
    """JSON that every parser accepts: no NaN, no Infinity (``json.dumps`` writes both by
    default, and they are not JSON)."""
    return json.dumps(finite(value), allow_nan=False)
