"""The recorder's contract: its counters and what it reads and (playing back) puts. Imports
only ``common``.

It listens to everything; playing a recording back puts frames and scans, on a stack that runs
no live sensor only: a replay must never reach a live robot's keys.
"""

from __future__ import annotations

from common.access import Access, Shape, service_access
from common.counters import COMMON

RECEIVED = "received"
WRITTEN = "written"
DROPPED = "dropped"  # the writer's queue was full

COUNTERS = frozenset({*COMMON, RECEIVED, WRITTEN, DROPPED})
PER_CAMERA: frozenset[str] = frozenset()

SERVICE = "recorder"


def access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    replay = () if shape.live_sensors else (*shape.frames(), keys.scan())
    return {SERVICE: service_access(keys, SERVICE, *replay, read=(f"{keys.prefix}/**",))}
