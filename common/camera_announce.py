"""A camera source's side of the camera announcements (issue 31): each camera it publishes is
described on the bus (a CameraAnnouncement in a liveliness token's key, common/announce.py)
from the moment it starts publishing until it stops, so that the announcement lives exactly as
long as the source does (a source that is killed takes its announcements with it).

A source that does not know a camera's size yet (a camera that keeps its device's size, a ROS 2
image topic, before the first image) announces 0x0 and then the size of the first frame; the
size is announced again whenever it changes. Used by the camera process, the simulator, the
ROS 2 bridge and ``zstack play``.
"""

from __future__ import annotations

import dataclasses
import threading
from typing import Protocol

from common.announce import Announcer
from common.bus import Bus
from common.errors import ConfigError
from common.keys import Keys
from common.lifecycle import Closing
from common.messages import MAX_ANNOUNCED_RATE_HZ, CameraAnnouncement


class Described(Protocol):
    """What an announcement says of a camera, as its settings hold it: a camera's settings
    (services/camera/contract.py ``CameraSettings``), or a camera announced before (a
    recording's)."""

    @property
    def rate_hz(self) -> float: ...

    @property
    def mount_yaw_deg(self) -> float: ...

    @property
    def hfov_deg(self) -> float: ...

    @property
    def frame_id(self) -> str: ...

    @property
    def mount_height_m(self) -> float: ...

    @property
    def mount_x_m(self) -> float: ...

    @property
    def mount_y_m(self) -> float: ...


def announcement_of(
    camera: str,
    described: Described,
    *,
    source: str,
    zid: str,
    rate_hz: float | None = None,
    frame_id: str | None = None,
    width: int = 0,
    height: int = 0,
    depth: bool = False,
    mount_height_m: float | None = None,
) -> CameraAnnouncement:
    """The announcement of ``camera`` as ``described`` (its settings), put by ``source`` from
    the Zenoh session ``zid``: the one place an announcement is built. ``rate_hz`` (capped at
    the highest rate an announcement may carry), ``frame_id`` and ``mount_height_m``, when
    given, stand for the described ones; ``depth``: the source publishes aligned depth images
    of it too. ValueError for a description no announcement can carry."""
    return CameraAnnouncement(
        camera=camera,
        width=width,
        height=height,
        rate_hz=min(described.rate_hz if rate_hz is None else rate_hz, MAX_ANNOUNCED_RATE_HZ),
        mount_yaw_deg=described.mount_yaw_deg,
        hfov_deg=described.hfov_deg,
        frame_id=described.frame_id if frame_id is None else frame_id,
        source=source,
        depth=depth,
        mount_height_m=described.mount_height_m if mount_height_m is None else mount_height_m,
        mount_x_m=described.mount_x_m,
        mount_y_m=described.mount_y_m,
        zid=zid,
    )


class CameraAnnouncements(Closing):
    """The announcements of the cameras one source publishes on ``keys`` (its robot's
    prefix), each saying it comes from ``source`` (``camera``, ``sim``, ``ros2``, ``play``)
    and from ``bus``'s Zenoh session (``zid``), the one that must publish their depth.
    Thread-safe: :meth:`saw` may be called from any thread, for every frame."""

    def __init__(self, bus: Bus, keys: Keys, source: str) -> None:
        self._bus = bus
        self._keys = keys
        self._source = source
        self._lock = threading.Lock()
        self._announcers: dict[str, Announcer[CameraAnnouncement]] = {}

    def announce(
        self,
        camera: str,
        described: Described,
        *,
        rate_hz: float | None = None,
        frame_id: str | None = None,
        width: int = 0,
        height: int = 0,
        depth: bool = False,
        mount_height_m: float | None = None,
    ) -> CameraAnnouncement:
        """Announce ``camera`` as ``described`` (its settings; :func:`announcement_of` says
        what the keywords change), instead of what was announced of it before.
        ConfigError (one line) for a description no announcement can carry (a frame id of
        over 128 characters)."""
        try:
            message = announcement_of(
                camera, described, source=self._source,
                zid=self._bus.zid,  # the session that publishes its frames and depth
                rate_hz=rate_hz, frame_id=frame_id, width=width, height=height, depth=depth,
                mount_height_m=mount_height_m,
            )  # fmt: skip
        except ValueError as exc:
            raise ConfigError(f"camera {camera!r} cannot be announced: {exc}") from exc
        with self._lock:
            announcer = self._announcers.get(camera)
            if announcer is None:
                announcer = self._announcers[camera] = Announcer(
                    self._bus, lambda chunk: self._keys.camera_announcement(camera, chunk)
                )
            announcer.update(message)
        return message

    def saw(self, camera: str, width: int, height: int, frame_id: str | None = None) -> None:
        """A frame of ``width`` x ``height`` (with header ``frame_id``, when the source takes
        it from its frames) was published on ``camera``: announce what is new of it. Cheap
        when nothing is (a few comparisons); nothing for a camera not announced. A frame id no
        announcement can carry (over 128 characters) is left as it was."""
        with self._lock:
            announcer = self._announcers.get(camera)
            current = announcer.current if announcer is not None else None
            if announcer is None or current is None:
                return
            frame_id = current.frame_id if frame_id is None else frame_id
            if (current.width, current.height, current.frame_id) == (width, height, frame_id):
                return
            try:
                new = dataclasses.replace(current, width=width, height=height, frame_id=frame_id)
            except ValueError:
                new = dataclasses.replace(current, width=width, height=height)
            announcer.update(new)

    def current(self, camera: str) -> CameraAnnouncement | None:
        """What is announced of ``camera`` now (None when nothing is)."""
        with self._lock:
            announcer = self._announcers.get(camera)
            return announcer.current if announcer is not None else None

    def withdraw(self, camera: str) -> None:
        """``camera`` is no longer published: its announcement goes."""
        with self._lock:
            announcer = self._announcers.pop(camera, None)
        if announcer is not None:
            announcer.close()

    def close(self) -> None:
        """Every announcement goes."""
        with self._lock:
            announcers, self._announcers = list(self._announcers.values()), {}
        for announcer in announcers:
            announcer.close()
