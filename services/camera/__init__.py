"""The camera: frames from a source (sample photo, image, folder, video, device) onto the bus.

What other packages may use is exported here (the detector's ``detect`` reads videos and
devices through it, so both accept the same forms):

    is_stream        whether a spec names a video file or a camera device
    open_stream      open one as a CaptureSource (read, fps, frame_count, close)
    CaptureSource    a video file or device through OpenCV
    VIDEO_EXTENSIONS the extensions taken for videos
"""

from typing import TYPE_CHECKING

from common.lazy import exports

if TYPE_CHECKING:
    from services.camera.sources import VIDEO_EXTENSIONS, CaptureSource, is_stream, open_stream

__all__ = ["VIDEO_EXTENSIONS", "CaptureSource", "is_stream", "open_stream"]
# Imported on first use: the camera's contract (services/camera/contract.py) loads no OpenCV.
__getattr__ = exports(__name__, dict.fromkeys(__all__, "services.camera.sources"))
