"""The metrics service's contract: its own counters, the counters of other services it reads,
and what it reads and serves. Imports only ``common`` and other services' contracts.

What it reads of another service's counters is named here through that service's contract, so
that a renamed counter fails type-checking, and a unit test checks each is one the writer
declares (tests/unit/metrics/test_contract.py).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated

from common.access import Access, Shape, service_access
from common.counters import COMMON
from common.errors import ConfigError
from common.setting_checks import Range, check_bounds
from services.detector import contract as detector

CAMERAS_REFUSED = "cameras_refused"  # detections of cameras over max_cameras
DETECTIONS_UNANNOUNCED = "detections_unannounced"  # of a camera with no live announcement
DUPLICATE_DETECTIONS = "duplicate_detections"
CLASS_NAMES_REFUSED = "class_names_refused"


def refused(why: str) -> str:
    """The counter of counters or figures not believed for ``why`` (services/metrics/trust.py)."""
    return f"refused.{why}"


COUNTERS = frozenset(
    {*COMMON, CAMERAS_REFUSED, DETECTIONS_UNANNOUNCED, DUPLICATE_DETECTIONS, CLASS_NAMES_REFUSED}
)
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
        detector.DEPTH_IN,
        detector.DEPTH_UNPAIRED,
    )
}
#: ... and those it reads for each camera (``<name>.<camera>``).
READS_PER_CAMERA: Mapping[str, tuple[str, ...]] = {
    "detector": (
        detector.FRAMES_IN,
        detector.DROPPED,
        detector.SERVING,
        detector.DEPTH_IN,
        detector.DEPTH_UNPAIRED,
    )
}

#: The detector's depth counters (issue 32), totals and ``<name>.<camera>``: depth images
#: taken, and colour frames of a depth camera with no depth image within the pairing
#: tolerance.
DEPTH_IN = detector.DEPTH_IN
DEPTH_UNPAIRED = detector.DEPTH_UNPAIRED

SERVICE = "metrics"


def access(shape: Shape) -> dict[str, Access]:
    keys, pool = shape.keys, shape.pool_keys()
    return {
        SERVICE: service_access(
            keys,
            SERVICE,
            read=(keys.all_detections(), keys.cmd_vel(), keys.all_counters()),
            serve=(keys.metrics(),),
            # The cameras announced, and the pool's members, their announcements (capacity,
            # robots) and what each serves, under the pool's prefix.
            watch=(
                keys.all_camera_announcements(),
                pool.all_pool_members(),
                pool.all_worker_announcements(),
                pool.all_pool_serving(),
            ),
        )
    }


# -- settings -------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True, kw_only=True)
class MetricsSettings:
    """The sliding window the percentiles cover, how often the report is logged, how much
    per-second history (FPS over time) is kept, and the optional Prometheus endpoint.

    ``prometheus_port`` 0 turns the endpoint off; it listens on ``prometheus_host`` (loopback by
    default, so that nothing is exposed to the network unless asked for).

    What is believed (services/metrics/trust.py): counters only from a known service on its own
    key, at most ``max_counters_per_service`` names each; a detector's stage times only within
    0..``max_timing_ms``. The rest is refused and counted as ``metrics.refused.<why>``. At most
    ``max_classes`` distinct class names are counted; a name beyond them is counted as
    ``metrics.class_names_refused`` (names longer than 128 characters never decode).
    Counters of a detector worker the config does not name (another host's pool worker,
    ``detector_<worker_id>``) are believed for the first ``max_workers`` such names heard; a
    further one is refused (``metrics.refused.too_many_workers``).
    """

    window_s: Annotated[float, Range(0.1, 3600)] = 10.0
    report_period_s: Annotated[float, Range(0.1, 3600)] = 5.0
    history_s: Annotated[float, Range(1, 86400)] = 600.0
    prometheus_port: Annotated[int, Range(0, 65535)] = 0  # 0 = off
    prometheus_host: str = "127.0.0.1"
    max_counters_per_service: Annotated[int, Range(1, 2000)] = 256
    max_timing_ms: Annotated[float, Range(0.001, 1e9)] = 1e6
    max_classes: Annotated[int, Range(1, 10000)] = 1000
    max_workers: Annotated[int, Range(0, 1000)] = 32

    def __post_init__(self) -> None:
        check_bounds(self, "metrics", MetricsSettings)
        if not self.prometheus_host:
            raise ConfigError("metrics.prometheus_host must not be empty")


#: The stack config's tables this service reads (stack/config.py's Config has each).
SETTINGS_TABLES = {"metrics": MetricsSettings}
