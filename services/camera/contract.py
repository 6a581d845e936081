"""The camera's contract: its counters and what each camera process puts. Imports only
``common``.

Each camera is a process and a principal of its own (``camera`` for the first camera,
``camera_<name>`` for each further one: ``Config.camera_services``); it puts its own camera's
frames and depth images only, announces its own camera only (its CameraAnnouncement tokens),
and reads nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from common.access import Access, Shape, service_access
from common.counters import COMMON
from common.errors import ConfigError
from common.limits import MAX_IMAGE_SIDE
from common.setting_checks import Range, check_bounds

FRAMES_OUT = "frames_out"
BAD_IMAGES = "bad_images"  # a file of a folder source that is no image
SOURCE_LOST = "source_lost"
SOURCE_REOPENED = "source_reopened"
SOURCE_REOPEN_FAILED = "source_reopen_failed"
DEPTH_OUT = "depth_out"  # depth images published (one per colour frame of a depth source)
BAD_DEPTH = "bad_depth"  # a depth image that cannot be used: that colour frame goes without
DEPTH_MISSING = "depth_missing"  # a colour frame of a depth source that came with no depth

COUNTERS = frozenset(
    {
        *COMMON,
        FRAMES_OUT,
        BAD_IMAGES,
        SOURCE_LOST,
        SOURCE_REOPENED,
        SOURCE_REOPEN_FAILED,
        DEPTH_OUT,
        BAD_DEPTH,
        DEPTH_MISSING,
    }
)
PER_CAMERA: frozenset[str] = frozenset()  # each process is one camera's

#: A camera feeds a live robot's sensors into the stack: no recording may be played onto it.
LIVE_SENSOR = True
#: Its work loop publishes counters on every pass: its heartbeat (deploy/watchdog.py).
HEARTBEAT = True


def access(shape: Shape) -> dict[str, Access]:
    """Each camera process puts its own camera's frames and depth images and announces its own
    camera."""
    keys = shape.keys
    return {
        name: service_access(
            keys,
            name,
            keys.frame(camera),
            keys.depth(camera),
            token=(keys.health(name), keys.camera_announcements_of(camera)),
        )
        for camera, name in shape.cameras.items()
    }


# -- settings -------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True, kw_only=True)
class CameraSettings:
    """The frame source.

    ``source`` is one of: ``sample:<name>`` (a scikit-image photo: astronaut, cameraman, chelsea,
    coffee, rocket, motorcycle), a path to an image (repeated), a folder of images (looped), a
    video file (looped when ``loop``), ``device:<index or /dev/videoN>`` (webcam / V4L2), or a
    network stream's URL (``rtsp://``, ``rtsps://``, ``http(s)://``, ``rtmp://``, ``udp://``,
    ``tcp://``, ``srt://``; read by OpenCV's FFmpeg).
    ``resize`` is (width, height), or (0, 0) to keep the source size. ``jpeg_quality`` 0 sends
    raw bgr8; 1..100 sends JPEG at that quality. ``hfov_deg`` is the horizontal field of view,
    which turns a pixel column into a bearing (the controller and the simulator use it).
    ``mount_yaw_deg`` is where the camera looks on the robot, counter-clockwise from the robot's
    forward axis (front 0, left 90, rear 180 or -180): the controller turns a bearing in the
    image into one in the robot's frame with it, and the simulator renders with it.
    A device or stream that gave frames and then stops (unplugged, reset) is reopened every
    ``reopen_period_s`` until it gives frames again (services/camera/reopen.py); one that gives
    none at start-up stops the camera with one line.

    Depth (docs/configuration.md, "RGB-D cameras"): ``realsense:[<serial>]`` and
    ``oak:[<mxid>]`` sources give colour with depth aligned to it (optional extras);
    ``depth_source``, a folder of 16-bit PNGs beside a colour folder ``source``, pairs each
    colour image with the depth PNG of the same file stem, read in units of ``depth_scale_m``
    metres, with ``intrinsics`` ``[fx, fy, cx, cy]`` in pixels of the images (all 0: from
    ``hfov_deg``, the principal point at the centre). ``depth_min_m``/``depth_max_m``: the
    sensor's valid range, published with each depth image (0 max: not stated).
    ``mount_height_m`` (the optical centre above the floor, 0 = unknown), ``mount_x_m``
    (forward) and ``mount_y_m`` (left) say where the camera stands on the robot, from its base.
    """

    source: str = "sample:cameraman"
    rate_hz: Annotated[float, Range(0.1, 1000)] = 10.0
    resize: tuple[int, int] = (0, 0)
    jpeg_quality: Annotated[int, Range(0, 100)] = 0
    frame_id: str = "camera"
    loop: bool = True
    hfov_deg: Annotated[float, Range(1, 179)] = 60.0
    mount_yaw_deg: Annotated[float, Range(-180, 180)] = 0.0
    reopen_period_s: Annotated[float, Range(0.05, 60)] = 1.0
    depth_source: str = ""
    depth_scale_m: Annotated[float, Range(0.0001, 1)] = 0.001
    intrinsics: Annotated[tuple[float, float, float, float], Range(0, 100000)] = (
        0.0,
        0.0,
        0.0,
        0.0,
    )
    depth_min_m: Annotated[float, Range(0, 100)] = 0.0
    depth_max_m: Annotated[float, Range(0, 1000)] = 0.0
    mount_height_m: Annotated[float, Range(0, 10)] = 0.0
    mount_x_m: Annotated[float, Range(-10, 10)] = 0.0
    mount_y_m: Annotated[float, Range(-10, 10)] = 0.0

    def __post_init__(self) -> None:
        check_bounds(self, "camera", CameraSettings)
        if (
            min(self.resize) < 0
            or max(self.resize) > MAX_IMAGE_SIDE
            or (0 in self.resize and self.resize != (0, 0))
        ):
            raise ConfigError(
                f"camera.resize must be [w, h] within 1..{MAX_IMAGE_SIDE} or [0, 0], "
                f"got {list(self.resize)}"
            )
        fx, fy, _, _ = self.intrinsics
        if any(self.intrinsics) and not (fx > 0 and fy > 0):
            raise ConfigError(
                "camera.intrinsics must be [fx, fy, cx, cy] with fx, fy > 0, or all 0 (from "
                f"hfov_deg), got {list(self.intrinsics)}"
            )
        if self.depth_max_m and self.depth_min_m >= self.depth_max_m:
            raise ConfigError(
                f"camera.depth_min_m ({self.depth_min_m:g}) must be below camera.depth_max_m "
                f"({self.depth_max_m:g}), or depth_max_m 0 (not stated)"
            )


#: The stack config's tables this service reads (stack/config.py's Config has each).
SETTINGS_TABLES = {"camera": CameraSettings}
