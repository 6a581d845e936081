"""The depth scan stage's contract: its counters and what it puts and reads. Imports only
``common``.

The stage (services/depthscan/service.py, a thin node over the depthscan/ library) turns each
announced depth camera's images into that camera's virtual scan, the way depthimage_to_laserscan
does, and keeps the depth cameras' short memory (depthscan/local_map.py), moved by the
controller's commands. It puts the virtual scans, the remembered scan and how far ahead the
floor is known; only the controller reads them to decide (the viewer shows the virtual scans,
the recorder keeps all three and the ROS 2 bridge publishes them).

Its settings are the controller's ``depth_*`` settings ([controller] in the stack config): the
scans are made and judged by one set of figures, declared once (services/controller/contract.py).
"""

from __future__ import annotations

from common.access import Access, Shape, service_access
from common.counters import COMMON, input_counters

# Its input, each counted by its fate (common/counters.py ``input_counter``): ``depth_in``,
# ``depth_stale`` ..., for each announced camera too.
DEPTH = "depth"
#: Depth frames of a camera not announced, or announced without depth: ignored.
DEPTH_UNANNOUNCED = "depth_unannounced"
#: Depth frames of a camera whose height above the floor is unknown: no virtual scan.
DEPTH_NO_MOUNT = "depth_no_mount"
#: Depth frames whose intrinsics or camera mounting are implausible: no virtual scan.
DEPTH_IMPLAUSIBLE = "depth_implausible"
#: Depth images of more than ``depth_max_pixels``: dropped before they are converted.
DEPTH_OVERSIZE = "depth_oversize"
#: Errors while making a virtual scan (the stage's thread logs them and goes on).
DEPTH_ERRORS = "depth_errors"
#: Depth frames replaced by a newer one of their camera before they were looked at.
DEPTH_DROPPED = "depth_dropped"
#: The depth map could not be written to, or read from, its file (issue 38).
DEPTH_MEMORY_ERRORS = "depth_memory_errors"
# -- depth from the announced source only (issue 38) --
#: Depth frames put by a Zenoh session other than the one that announced their camera
#: (``CameraAnnouncement.zid``): dropped before they are decoded.
DEPTH_FOREIGN = "depth_foreign"
#: A gauge, per camera: 1 while its depth frames keep arriving older than the one held (at
#: least ``depth_late_warn_count`` within ``depth_late_warn_window_s``), the sign of a second
#: stream on its key; the total is how many cameras are so now. The metrics warn of it.
DEPTH_SECOND_STREAM = "depth_second_stream"
DEPTH_TRUST_PER_CAMERA = frozenset({DEPTH_FOREIGN, DEPTH_SECOND_STREAM})
# --
#: The controller's commands heard (the memory's odometry), and those not decodable or stale.
COMMANDS_IN = "commands_in"
#: Virtual scans put, and the memory's (remembered and known floor) put.
SCANS_OUT = "scans_out"
MEMORY_OUT = "memory_out"

PER_CAMERA = frozenset(
    {
        *input_counters(DEPTH),
        DEPTH_NO_MOUNT,
        DEPTH_DROPPED,
        DEPTH_IMPLAUSIBLE,
        DEPTH_OVERSIZE,
        *DEPTH_TRUST_PER_CAMERA,
    }
)
COUNTERS = frozenset(
    {
        *COMMON,
        *PER_CAMERA,
        DEPTH_UNANNOUNCED,
        DEPTH_ERRORS,
        DEPTH_MEMORY_ERRORS,
        COMMANDS_IN,
        SCANS_OUT,
        MEMORY_OUT,
    }
)

SERVICE = "depthscan"
#: Its work loop publishes counters on every pass: its heartbeat (deploy/watchdog.py).
HEARTBEAT = True


def access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    return {
        SERVICE: service_access(
            keys,
            SERVICE,
            keys.all_virtual_scans(),
            keys.remembered_scan(),
            keys.known_floor(),
            # The depth images; the controller's commands (the memory's odometry: only the
            # controller may put them).
            read=(keys.all_depths(), keys.cmd_vel()),
            watch=(keys.all_camera_announcements(),),  # its cameras: the announced ones
        )
    }


#: It reads the controller's ``depth_*`` settings; no table of its own.
SETTINGS_TABLES: dict[str, type] = {}
