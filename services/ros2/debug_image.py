"""The debug image yolo_ros users look at in RViz or Foxglove: a frame with its detections
drawn on it. Pure: frames and detections in, a jpeg Frame out.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from common.annotate import annotate
from common.frames import frame_to_bgr, image_to_frame
from common.limits import DEFAULT_MAX_FRAME_PIXELS
from common.messages import Detections, Frame

FRAMES_KEPT = 30  # a detector never lags more than this many frames behind its camera


class FrameCache:
    """The last frames seen, by capture stamp, to pair with the detections made on them."""

    def __init__(self, size: int = FRAMES_KEPT) -> None:
        self._frames: OrderedDict[int, Frame] = OrderedDict()
        self._size = size
        self._lock = threading.Lock()

    def add(self, frame: Frame) -> None:
        with self._lock:
            self._frames[frame.header.stamp_ns] = frame
            while len(self._frames) > self._size:
                self._frames.popitem(last=False)

    def take(self, stamp_ns: int) -> Frame | None:
        """The frame captured at ``stamp_ns`` (and forget it and every older one)."""
        with self._lock:
            frame = self._frames.get(stamp_ns)
            if frame is not None:
                while self._frames and next(iter(self._frames)) <= stamp_ns:
                    self._frames.popitem(last=False)
            return frame


def debug_image(
    frame: Frame, dets: Detections, jpeg_quality: int, max_pixels: int = DEFAULT_MAX_FRAME_PIXELS
) -> Frame:
    """``frame`` with ``dets`` drawn on it, as a jpeg Frame with the frame's header.
    Raises common.errors.ImageError if the frame's pixels cannot be read, or (ImageTooLarge)
    if it has more than ``max_pixels``."""
    drawn = annotate(frame_to_bgr(frame, max_pixels), dets.boxes, dets.class_names)
    return image_to_frame(drawn, frame.header, jpeg_quality=jpeg_quality)
