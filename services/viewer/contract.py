"""The live view's contract: its counters and what it reads. Imports only ``common``.

It reads what it shows (and queries the metrics); it announces itself and puts nothing but its
counters.
"""

from __future__ import annotations

from common.access import Access, Shape, service_access
from common.counters import COMMON

FRAMES_IN = "frames_in"
DETECTIONS_UNPAIRED = "detections_unpaired"
IMAGES_OUT = "images_out"
IMAGES_DROPPED = "images_dropped"
UNSHOWABLE = "unshowable"

COUNTERS = frozenset(
    {*COMMON, FRAMES_IN, DETECTIONS_UNPAIRED, IMAGES_OUT, IMAGES_DROPPED, UNSHOWABLE}
)
PER_CAMERA: frozenset[str] = frozenset()

SERVICE = "viewer"


def access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    return {
        SERVICE: service_access(
            keys,
            SERVICE,
            read=(
                keys.all_frames(),
                keys.all_detections(),
                keys.scan(),
                keys.cmd_vel(),
                keys.controller_status(),
                keys.sim_truth(),
            ),
        )
    }
