"""The metrics service's contract: its own counters, the counters of other services it reads,
and what it reads and serves. Imports only ``common`` and other services' contracts.

What it reads of another service's counters is named here through that service's contract, so
that a renamed counter fails type-checking, and a unit test checks each is one the writer
declares (tests/unit/metrics/test_contract.py).
"""

from __future__ import annotations

from collections.abc import Mapping

from common.access import Access, Shape, service_access
from common.counters import COMMON
from services.detector import contract as detector

CAMERAS_REFUSED = "cameras_refused"  # detections of cameras over max_cameras
DUPLICATE_DETECTIONS = "duplicate_detections"
CLASS_NAMES_REFUSED = "class_names_refused"


def refused(why: str) -> str:
    """The counter of counters or figures not believed for ``why`` (services/metrics/trust.py)."""
    return f"refused.{why}"


COUNTERS = frozenset({*COMMON, CAMERAS_REFUSED, DUPLICATE_DETECTIONS, CLASS_NAMES_REFUSED})
PER_CAMERA: frozenset[str] = frozenset()

#: Other services' counters it reads by name, by the package that writes them (every other
#: ``<name>.<camera>`` counter is shown under its camera whatever its name).
READS: Mapping[str, tuple[str, ...]] = {
    "detector": (
        detector.FRAMES_IN,
        detector.DROPPED,
        detector.BATCHES,
        detector.BATCHED_FRAMES,
        detector.SERVING,
        detector.POOL_LOAD_PERMILLE,
        detector.POOL_MEMBERS,
        detector.CAMERAS_GAINED,
        detector.CAMERAS_LOST,
    )
}
#: ... and those it reads for each camera (``<name>.<camera>``).
READS_PER_CAMERA: Mapping[str, tuple[str, ...]] = {
    "detector": (detector.FRAMES_IN, detector.DROPPED, detector.SERVING)
}

SERVICE = "metrics"


def access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    return {
        SERVICE: service_access(
            keys,
            SERVICE,
            read=(keys.all_detections(), keys.cmd_vel(), keys.all_counters()),
            serve=(keys.metrics(),),
        )
    }
