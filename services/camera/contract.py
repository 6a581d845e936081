"""The camera's contract: its counters and what each camera process puts. Imports only
``common``.

Each camera is a process and a principal of its own (``camera`` for the first camera,
``camera_<name>`` for each further one: ``Config.camera_services``); it puts its own camera's
frames only, and reads nothing.
"""

from __future__ import annotations

from common.access import Access, Shape, service_access
from common.counters import COMMON

FRAMES_OUT = "frames_out"
BAD_IMAGES = "bad_images"  # a file of a folder source that is no image
SOURCE_LOST = "source_lost"
SOURCE_REOPENED = "source_reopened"
SOURCE_REOPEN_FAILED = "source_reopen_failed"

COUNTERS = frozenset(
    {*COMMON, FRAMES_OUT, BAD_IMAGES, SOURCE_LOST, SOURCE_REOPENED, SOURCE_REOPEN_FAILED}
)
PER_CAMERA: frozenset[str] = frozenset()  # each process is one camera's

#: A camera feeds a live robot's sensors into the stack: no recording may be played onto it.
LIVE_SENSOR = True


def access(shape: Shape) -> dict[str, Access]:
    """Each camera process puts its own camera's frames."""
    return {
        name: service_access(shape.keys, name, shape.keys.frame(camera))
        for camera, name in shape.cameras.items()
    }
