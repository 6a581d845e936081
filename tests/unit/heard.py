"""What a listener hears of the camera announcements on an in-process bus: the unit tests of
every camera source (camera, simulator, ROS 2 bridge, play) watch them with this."""

from __future__ import annotations

from collections.abc import Callable

from common.announce import Announced, announced_cameras
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import CameraAnnouncement


def heard_cameras(
    hub: MemoryHub,
    keys: Keys,
    on_change: Callable[[], None] | None = None,
    *,
    principal: str | None = None,
) -> Announced[CameraAnnouncement]:
    """Every camera announced on ``keys``, as a pool worker would see them (joined as
    ``principal``: a hub with access rules needs one); garbage fails."""

    def bad(key: str, error: Exception) -> None:
        raise AssertionError(f"a bad announcement on {key}: {error}")

    return announced_cameras(hub.join("listener", principal=principal), keys, on_change, bad)
