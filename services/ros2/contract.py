"""The ROS 2 bridge's contract: its counters and what it puts and reads. Imports only
``common``.

The bridge feeds the robot's cameras and laser into the stack, and the stack's detections and
commands out to the robot (held at zero by the controller's status).
"""

from __future__ import annotations

from common.access import Access, Shape, service_access
from common.counters import COMMON

DETECTIONS_OUT = "detections_out"
COMMANDS_OUT = "commands_out"
DEBUG_IMAGES_OUT = "debug_images_out"


def topic_in(ros_type: str) -> str:
    """The counter of messages of ``ros_type`` (``sensor_msgs/msg/Image``) taken in:
    ``image_in``."""
    return f"{ros_type.rsplit('/', 1)[-1].lower()}_in"


#: Its own counts; the command gate (common/command_gate.py) adds ``commands_<why>`` and
#: ``stops_<why>`` for what it refused or replaced by zero.
COUNTERS = frozenset({*COMMON, DETECTIONS_OUT, COMMANDS_OUT, DEBUG_IMAGES_OUT})
PER_CAMERA: frozenset[str] = frozenset()

SERVICE = "ros2"
#: It feeds a live robot's sensors into the stack: no recording may be played onto it.
LIVE_SENSOR = True


def access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    return {
        SERVICE: service_access(
            keys,
            SERVICE,
            *shape.frames(),
            keys.scan(),
            read=(
                keys.all_frames(),
                keys.all_detections(),
                keys.cmd_vel(),
                keys.controller_status(),
            ),
        )
    }
