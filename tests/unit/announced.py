"""Cameras announced as their sources would (common/announce.py), for in-process tests of the
services that take their cameras from the announcements (the controller, the metrics)."""

from __future__ import annotations

from functools import partial
from typing import Any

from common.announce import Announcer
from common.keys import Keys
from common.memory_bus import MemoryBus, MemoryHub
from common.messages import CameraAnnouncement
from services.camera.contract import CameraSettings


def announcement(name: str, camera: CameraSettings, **fields: Any) -> CameraAnnouncement:
    """What a source announces of camera ``name`` configured as ``camera`` (640x480 frames),
    then ``fields``."""
    mine = {
        "camera": name, "width": 640, "height": 480, "rate_hz": camera.rate_hz,
        "mount_yaw_deg": camera.mount_yaw_deg, "hfov_deg": camera.hfov_deg,
        "frame_id": camera.frame_id, "source": "test",
    }  # fmt: skip
    return CameraAnnouncement(**{**mine, **fields})


class Sources:
    """Each camera's source on a participant of its own on ``hub``: :meth:`announce` a camera
    (again, with other fields), :meth:`withdraw` it (its source's session closes)."""

    def __init__(self, hub: MemoryHub, keys: Keys) -> None:
        self.hub, self.keys = hub, keys
        self.live: dict[str, tuple[MemoryBus, Announcer[CameraAnnouncement]]] = {}

    def announce(self, name: str, camera: CameraSettings | None = None, **fields: Any) -> None:
        if name not in self.live:
            bus = self.hub.join(f"source_{name}")
            self.live[name] = (bus, Announcer(bus, partial(self.keys.camera_announcement, name)))
        self.live[name][1].update(announcement(name, camera or CameraSettings(), **fields))

    def withdraw(self, name: str) -> None:
        bus, _ = self.live.pop(name)
        bus.close()

    def close(self) -> None:
        for name in list(self.live):
            self.withdraw(name)
