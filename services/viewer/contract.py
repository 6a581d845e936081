"""The live view's contract: its counters and what it reads. Imports only ``common``.

It reads what it shows (and queries the metrics); it announces itself and puts nothing but its
counters.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from common.access import Access, Shape, service_access
from common.counters import COMMON
from common.errors import ConfigError
from common.setting_checks import Length, Range, check_bounds, check_lengths

FRAMES_IN = "frames_in"
DETECTIONS_UNPAIRED = "detections_unpaired"
IMAGES_OUT = "images_out"
IMAGES_DROPPED = "images_dropped"
UNSHOWABLE = "unshowable"
DEPTH_IN = "depth_in"  # depth images heard (only while a client watches the camera's depth)
DEPTH_OUT = "depth_out"  # ... and sent

COUNTERS = frozenset(
    {
        *COMMON,
        FRAMES_IN,
        DETECTIONS_UNPAIRED,
        IMAGES_OUT,
        IMAGES_DROPPED,
        UNSHOWABLE,
        DEPTH_IN,
        DEPTH_OUT,
    }
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
                keys.all_depths(),
                keys.all_detections(),
                keys.scan(),
                keys.all_virtual_scans(),
                keys.cmd_vel(),
                keys.controller_status(),
                keys.sim_truth(),
            ),
            # Which cameras have depth, and where each stands on the robot.
            watch=(keys.all_camera_announcements(),),
        )
    }


# -- settings -------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True, kw_only=True)
class ViewerSettings:
    """A Foxglove WebSocket server that shows the stack live (docs/viewer.md).

    It listens on ``host``:``port``; loopback by default, because the view carries the camera's
    images: to watch from a laptop, tunnel the port over SSH, or set ``host = "0.0.0.0"`` on a
    network you trust (the view is read-only, but anyone who reaches it sees the camera).
    Behind that port, the Foxglove server itself listens on 127.0.0.1:``relay_port``, which only
    the viewer's front relays admitted clients to (0: a port the system picks free).
    Images are JPEG-encoded on the viewer's own thread at most ``image_rate_hz`` times a second
    at ``jpeg_quality``, scaled down to ``max_image_width`` pixels (0 keeps the frame's width);
    frames that arrive faster are dropped and counted. The metrics service is asked
    ``metrics_rate_hz`` times a second; the 3D scene (simulator only) is sent ``scene_rate_hz``
    times a second with the robot's last ``path_points`` positions as its path.
    A camera announced with depth has its depth image (16UC1, mm) sent as its colour images
    are, while a client watches it; detections with depth are drawn as 3D boxes at most
    ``image_rate_hz`` times a second per camera, each camera's lasting ``boxes_lifetime_s``
    from their capture stamp (they vanish when its detections stop; shorter than the
    detector's latency plus its period, they blink).

    Who may connect (docs/security.md, "The live view"): a client whose request carries an
    ``Origin`` header (every browser page) only if that origin is in ``allowed_origins``
    (exact ``scheme://host[:port]``); a native client (no Origin) always; and under the secure
    profile (``zenoh.auth`` not "none") only with ``?token=`` the ``viewer-token`` file of
    ``zenoh.credentials_dir`` in its URL. A connection that has not sent its whole request
    head within ``request_timeout_s`` is closed.
    """

    host: str = "127.0.0.1"
    # Not 8765: foxglove_bridge's default on a ROS 2 robot
    port: Annotated[int, Range(1, 65535)] = 8766
    # The Foxglove server's own, on 127.0.0.1; 0: any free one
    relay_port: Annotated[int, Range(0, 65535)] = 0
    image_rate_hz: Annotated[float, Range(0.1, 60)] = 5.0
    jpeg_quality: Annotated[int, Range(1, 100)] = 70
    # 0 keeps the frame's width; else at least 64
    max_image_width: Annotated[int, Range(0, 8192)] = 640
    metrics_rate_hz: Annotated[float, Range(0.1, 10)] = 1.0
    scene_rate_hz: Annotated[float, Range(0.1, 50)] = 5.0
    path_points: Annotated[int, Range(2, 100_000)] = 1000
    # () lets in native clients only
    allowed_origins: Annotated[tuple[str, ...], Length(0, 100)] = ("https://app.foxglove.dev",)
    request_timeout_s: Annotated[float, Range(0.1, 60)] = 5.0
    boxes_lifetime_s: Annotated[float, Range(0.05, 60)] = 2.0

    def __post_init__(self) -> None:
        if not self.host:
            raise ConfigError("viewer.host must not be empty")
        check_bounds(self, "viewer", ViewerSettings)
        check_lengths(self, "viewer", ViewerSettings)
        for origin in self.allowed_origins:
            if origin == "*" or "://" not in origin:
                raise ConfigError(
                    f"viewer.allowed_origins: {origin!r} is not an origin "
                    "(scheme://host[:port]; wildcards are not accepted)"
                )
        if self.relay_port == self.port:
            raise ConfigError(
                f"viewer.relay_port must differ from viewer.port ({self.port}): the front "
                "listens on one and relays to the other (0: any free port)"
            )
        if self.max_image_width != 0 and self.max_image_width < 64:
            raise ConfigError(
                f"viewer.max_image_width must be 0 (keep) or 64..8192, got {self.max_image_width}"
            )


#: The stack config's tables this service reads (stack/config.py's Config has each).
SETTINGS_TABLES = {"viewer": ViewerSettings}
