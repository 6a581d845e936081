"""An Intel RealSense camera (D400 series and the like) through pyrealsense2, the ``realsense``
extra: colour (bgr8) and depth (z16) at :data:`SIZE` and :data:`FPS`, depth aligned to the
colour stream by ``rs.align``, with the colour stream's intrinsics and the device's depth scale.

Device I/O only (the conversion is services/camera/depth.py, unit-tested); this module runs
only with a camera plugged in, which no test machine of ours has. A missing pyrealsense2, a
missing libusb or no camera is one line (ConfigError), never a traceback.
"""

from __future__ import annotations

import contextlib
from types import ModuleType
from typing import cast

import numpy as np

from common.errors import ConfigError
from common.images import Image
from services.camera.depth import DepthImage, device_depth
from services.camera.extras import import_extra

#: The colour and depth streams' size and rate: one that every D400 camera gives for both.
SIZE = (640, 480)
FPS = 30
#: How long a frame may take before the camera counts as stopped (then it is reopened).
FRAME_TIMEOUT_MS = 2000


def open_realsense(serial: str) -> RealSenseSource:
    """The RealSense camera of ``serial`` (the first one found when empty)."""
    spec = "camera source " + repr(f"realsense:{serial}")
    rs = import_extra("pyrealsense2", "realsense", spec)
    return RealSenseSource(rs, serial, spec)


class RealSenseSource:
    """Colour frames with depth aligned to them (``depth()``: the last frame's)."""

    live = True
    has_depth = True

    def __init__(self, rs: ModuleType, serial: str, spec: str) -> None:
        self._rs = rs
        self.description = f"RealSense {serial or '(first found)'}"
        try:
            found = [d.get_info(rs.camera_info.serial_number) for d in rs.context().devices]
        except RuntimeError as exc:
            raise ConfigError(f"{spec}: cannot list RealSense cameras ({exc})") from exc
        if not found:
            raise ConfigError(f"{spec}: no RealSense camera found (pyrealsense2 sees none)")
        if serial and serial not in found:
            raise ConfigError(f"{spec}: no RealSense camera of that serial; found {found}")
        config = rs.config()
        if serial:
            config.enable_device(serial)
        width, height = SIZE
        config.enable_stream(rs.stream.color, width, height, rs.format.bgr8, FPS)
        config.enable_stream(rs.stream.depth, width, height, rs.format.z16, FPS)
        self._pipeline = rs.pipeline()
        try:
            profile = self._pipeline.start(config)
        except RuntimeError as exc:
            raise ConfigError(
                f"{spec}: cannot start colour and depth at {width}x{height} {FPS} fps ({exc})"
            ) from exc
        self._scale_m = float(profile.get_device().first_depth_sensor().get_depth_scale())
        stream = profile.get_stream(rs.stream.color).as_video_stream_profile()
        k = stream.get_intrinsics()
        self._intrinsics = (float(k.fx), float(k.fy), float(k.ppx), float(k.ppy))
        self._align = rs.align(rs.stream.color)
        self._depth: np.ndarray | None = None
        self._colour: Image | None = None
        self.frames_read = 0

    def read(self) -> Image | None:
        """The next colour frame (its aligned depth kept for ``depth()``); None when the
        camera stopped giving frames; ConfigError when it never gave one."""
        self._colour = self._depth = None
        try:
            frames = self._pipeline.wait_for_frames(FRAME_TIMEOUT_MS)
            aligned = self._align.process(frames)
            colour, depth = aligned.get_color_frame(), aligned.get_depth_frame()
        except RuntimeError as exc:
            if not self.frames_read:
                raise ConfigError(
                    f"{self.description}: not one frame could be read ({exc})"
                ) from exc
            return None
        if not colour:
            if not self.frames_read:
                raise ConfigError(f"{self.description}: not one colour frame could be read")
            return None
        # Copies: the library reuses its buffers once the frames are released.
        self._colour = cast(Image, np.array(colour.get_data(), dtype=np.uint8, copy=True))
        if depth:
            self._depth = np.array(depth.get_data(), dtype=np.uint16, copy=True)
        self.frames_read += 1
        return self._colour

    def depth(self) -> DepthImage | None:
        if self._colour is None or self._depth is None:
            return None
        return device_depth(
            self._colour, self._depth, scale_m=self._scale_m, intrinsics=self._intrinsics
        )

    def close(self) -> None:
        # A camera already gone (unplugged) has nothing left to stop.
        with contextlib.suppress(RuntimeError):
            self._pipeline.stop()
