"""The simulator's contract: its counters and what it puts and reads. Imports only ``common``.

The simulator renders every camera from one world and plays the laser and the robot's base: it
puts every camera's frames, the scan and the ground truth, and reads the velocity commands.
"""

from __future__ import annotations

from common.access import Access, Shape, service_access
from common.counters import COMMON

FRAMES_OUT = "frames_out"  # in all and per camera
COMMANDS_OUT_OF_RANGE = "commands_out_of_range"  # beyond what the base takes: it stops
COMMANDS_FROM_SEVERAL_SOURCES = "commands_from_several_sources"

PER_CAMERA = frozenset({FRAMES_OUT})
COUNTERS = frozenset({*COMMON, FRAMES_OUT, COMMANDS_OUT_OF_RANGE, COMMANDS_FROM_SEVERAL_SOURCES})

SERVICE = "sim"
#: It feeds a (simulated) robot's sensors into the stack: no recording may be played onto it.
LIVE_SENSOR = True


def access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    return {
        SERVICE: service_access(
            keys,
            SERVICE,
            *shape.frames(),
            keys.scan(),
            keys.sim_truth(),
            read=(keys.cmd_vel(),),
        )
    }
