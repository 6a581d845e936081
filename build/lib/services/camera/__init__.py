"""The camera: frames from a source (sample photo, image, folder, video, device) onto the bus.

What other packages may use is exported here (the detector's ``detect`` reads videos and
devices through it, so both accept the same forms):

    is_stream        whether a spec names a video file or a camera device
    open_stream      open one as a CaptureSource (read, fps, frame_count, close)
    CaptureSource    a video file or device through OpenCV
    VIDEO_EXTENSIONS the extensions taken for videos
"""

from services.camera.sources import VIDEO_EXTENSIONS, CaptureSource, is_stream, open_stream

__all__ = ["VIDEO_EXTENSIONS", "CaptureSource", "is_stream", "open_stream"]
