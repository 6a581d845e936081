"""A Luxonis OAK camera (OAK-D and the like) through depthai 3, the ``oak`` extra: the RGB
camera (CAM_A, bgr8) and StereoDepth from the two mono cameras, depth aligned to the RGB
camera at the same :data:`SIZE`, synchronised on the device (a Sync node), with the RGB
camera's intrinsics from the device's calibration at that size.

Device I/O only (the conversion is services/camera/depth.py, unit-tested); this module runs
only with a camera plugged in, which no test machine of ours has. A missing depthai or no
camera is one line (ConfigError), never a traceback.
"""

from __future__ import annotations

import contextlib
import datetime
from types import ModuleType
from typing import Any, cast

import numpy as np

from common.errors import ConfigError
from common.images import Image
from services.camera.depth import DepthImage, device_depth, intrinsics_from_matrix
from services.camera.extras import import_extra

#: The RGB and depth images' size (4:3, the RGB sensor's own aspect: no crop) and rate.
SIZE = (640, 480)
FPS = 30.0
#: How long a frame may take before the camera counts as stopped (then it is reopened).
FRAME_TIMEOUT_S = 2.0


def open_oak(device_id: str) -> OakSource:
    """The OAK camera of ``device_id`` (its MxId/device id or IP; the first found when empty)."""
    spec = "camera source " + repr(f"oak:{device_id}")
    dai = import_extra("depthai", "oak", spec)
    return OakSource(dai, device_id, spec)


class OakSource:
    """RGB frames with depth aligned to them (``depth()``: the last frame's)."""

    live = True
    has_depth = True

    def __init__(self, dai: ModuleType, device_id: str, spec: str) -> None:
        self.description = f"OAK {device_id or '(first found)'}"
        # A closed queue (the device gone) raises this, not a RuntimeError.
        self._lost: tuple[type[BaseException], ...] = (
            RuntimeError,
            dai.MessageQueue.QueueException,
        )
        if not dai.Device.getAllAvailableDevices():
            raise ConfigError(f"{spec}: no OAK camera found (depthai sees none)")
        try:
            device = dai.Device(dai.DeviceInfo(device_id)) if device_id else dai.Device()
            self._pipeline, self._queue = _pipeline(dai, device)
            calibration = device.readCalibration()
            matrix = calibration.getCameraIntrinsics(dai.CameraBoardSocket.CAM_A, *SIZE)
            self._intrinsics = intrinsics_from_matrix(matrix)
            self._pipeline.start()
        except RuntimeError as exc:
            raise ConfigError(f"{spec}: cannot start RGB and stereo depth ({exc})") from exc
        self._colour: Image | None = None
        self._depth: np.ndarray | None = None
        self.frames_read = 0

    def read(self) -> Image | None:
        """The next RGB frame (its aligned depth kept for ``depth()``); None when the camera
        stopped giving frames; ConfigError when it never gave one."""
        self._colour = self._depth = None
        try:
            group: Any = self._queue.get(datetime.timedelta(seconds=FRAME_TIMEOUT_S))
            colour = group["colour"] if group is not None else None
            depth = group["depth"] if group is not None else None
        except self._lost:
            colour = depth = None
        if colour is None:
            if not self.frames_read:
                raise ConfigError(f"{self.description}: not one frame could be read")
            return None
        self._colour = cast(Image, np.array(colour.getCvFrame(), dtype=np.uint8, copy=True))
        if depth is not None:
            self._depth = np.array(depth.getFrame(), dtype=np.uint16, copy=True)
        self.frames_read += 1
        return self._colour

    def depth(self) -> DepthImage | None:
        if self._colour is None or self._depth is None:
            return None
        # StereoDepth's depth output is in millimetres.
        return device_depth(self._colour, self._depth, scale_m=0.001, intrinsics=self._intrinsics)

    def close(self) -> None:
        # A camera already gone (unplugged) has nothing left to stop.
        with contextlib.suppress(RuntimeError):
            self._pipeline.stop()


def _pipeline(dai: ModuleType, device: Any) -> tuple[Any, Any]:
    """RGB (CAM_A) and stereo depth aligned to it at SIZE, paired on the device by a Sync node
    into groups of ``colour`` and ``depth``: the pipeline and its output queue."""
    pipeline = dai.Pipeline(device)
    rgb = pipeline.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_A)
    colour = rgb.requestOutput(SIZE, dai.ImgFrame.Type.BGR888i, fps=FPS)
    stereo = pipeline.create(dai.node.StereoDepth).build(autoCreateCameras=True, fps=FPS)
    stereo.setDepthAlign(dai.CameraBoardSocket.CAM_A)
    stereo.setOutputSize(*SIZE)
    sync = pipeline.create(dai.node.Sync)
    colour.link(sync.inputs["colour"])
    stereo.depth.link(sync.inputs["depth"])
    # One, not blocking: the service reads at camera.rate_hz and takes the newest pair, never
    # a backlog of older ones.
    queue = sync.out.createOutputQueue(maxSize=1, blocking=False)
    return pipeline, queue
