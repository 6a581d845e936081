"""Which image the viewer sends next: a frame together with the detections made on it.

Frames wait (a few, by capture stamp) for their detections; a pair then waits in one slot for
the encoder, which takes it at its own rate. A newer pair replaces one not yet taken, and that
counts as dropped: the viewer never queues images, so it can never hold the stack back. When
no detections have come for ``unpaired_after_s`` (no detector running) the newest frame is
sent alone, so the camera can still be watched. Thread-safe: Zenoh's threads add, the
encoder's takes.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from common.messages import Detections, Frame

FRAMES_KEPT = 30  # a detector never lags more than this many frames behind its camera


class Pairing:
    def __init__(self, unpaired_after_s: float = 1.0, frames_kept: int = FRAMES_KEPT) -> None:
        self._frames: OrderedDict[int, Frame] = OrderedDict()
        self._kept = frames_kept
        self._unpaired_after_s = unpaired_after_s
        self._pair: tuple[Frame, Detections] | None = None
        self._newest: Frame | None = None
        self._last_detections = -float("inf")
        self._lock = threading.Lock()
        self.dropped = 0

    def add_frame(self, frame: Frame) -> None:
        with self._lock:
            self._frames[frame.header.stamp_ns] = frame
            while len(self._frames) > self._kept:
                self._frames.popitem(last=False)
            self._newest = frame

    def add_detections(self, dets: Detections, now: float) -> bool:
        """Pair ``dets`` with its frame (False when that frame was never seen or is gone)."""
        stamp_ns = dets.header.stamp_ns
        with self._lock:
            self._last_detections = now
            frame = self._frames.get(stamp_ns)
            if frame is None:
                return False
            while self._frames and next(iter(self._frames)) <= stamp_ns:
                self._frames.popitem(last=False)  # it and every older one: they are done
            if self._pair is not None:
                self.dropped += 1
            self._pair = (frame, dets)
            return True

    def take(self, now: float) -> tuple[Frame, Detections | None] | None:
        """The next image to send and its detections (None: a frame alone), or None."""
        with self._lock:
            if self._pair is not None:
                pair, self._pair = self._pair, None
                return pair
            if self._newest is not None and now - self._last_detections > self._unpaired_after_s:
                frame, self._newest = self._newest, None
                return frame, None
            return None
