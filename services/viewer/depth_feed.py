"""Each camera's depth images into the view, heard only while someone looks at them.

A camera announced with depth (CameraAnnouncement.depth) gets a depth channel; the viewer
subscribes to its depth key only while a client subscribes to that channel, since a depth image
is large (600 kB at 640x480) and most viewers never open it. Like the colour images, only the
newest image of each camera waits for the encoder, which decodes and sends it at
``image_rate_hz``: the viewer never queues depth either. Thread-safe: Zenoh's threads add, the
encoder's thread updates the subscriptions and takes.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Mapping
from functools import partial

from common.bus import Declared
from common.messages import CameraAnnouncement, DepthFrame
from common.node import Tally
from services.viewer import contract
from services.viewer.channels import Channels
from services.viewer.depth import depth_image

#: Subscribe a handler to a key (``Node.subscribe``): what the feed listens with.
Subscribe = Callable[[str, Callable[[bytes], None]], Declared]


class DepthFeed:
    """The depth images of ``cameras`` (the viewer's), on ``channels``."""

    def __init__(
        self, tally: Tally, channels: Channels, subscribe: Subscribe, cameras: Iterable[str]
    ) -> None:
        self.tally = tally
        self.channels = channels
        self._subscribe = subscribe
        self.cameras = tuple(cameras)
        self._lock = threading.Lock()
        self._subs: dict[str, Declared] = {}
        self._newest: dict[str, bytes] = {}

    def subscribed(self) -> set[str]:
        """The cameras whose depth is heard now."""
        return set(self._subs)

    def update(self, announced: Mapping[str, CameraAnnouncement]) -> None:
        """Make the depth channel of each camera announced with depth, and hear its depth
        only while a client watches that channel (on the encoder's thread)."""
        for camera in self.cameras:
            a = announced.get(camera)
            wanted = a is not None and a.depth and self.channels.depth(camera).has_sinks()
            sub = self._subs.get(camera)
            if wanted and sub is None:
                key = self.tally.keys.depth(camera)
                self._subs[camera] = self._subscribe(key, partial(self._add, camera))
            elif not wanted and sub is not None:
                del self._subs[camera]
                sub.undeclare()
                with self._lock:
                    self._newest.pop(camera, None)

    def _add(self, camera: str, payload: bytes) -> None:
        """A depth image heard: kept undecoded until the encoder takes it (most are replaced
        by a newer one first)."""
        self.tally.counters.add(contract.DEPTH_IN)
        with self._lock:
            self._newest[camera] = payload

    def send(self, max_width: int, unshowable: Callable[[str, ValueError], None]) -> None:
        """Send each camera's newest depth image, if one came since the last send."""
        with self._lock:
            taken, self._newest = self._newest, {}
        for camera, payload in taken.items():
            key = self.tally.keys.depth(camera)
            frame = self.tally.decode(key, DepthFrame.decode, payload)
            if frame is None:
                continue
            try:
                image = depth_image(frame, max_width)
            except ValueError as exc:
                unshowable("depth image", exc)
                continue
            self.channels.depth(camera).log(image, log_time=frame.header.stamp_ns)
            self.tally.counters.add(contract.DEPTH_OUT)

    def close(self) -> None:
        for sub in self._subs.values():
            sub.undeclare()
        self._subs.clear()
