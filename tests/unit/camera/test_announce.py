"""The camera process announces its camera (common/camera_announce.py) while it publishes:
run in-process on a MemoryHub with sources of its own, so that the test says when frames come."""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable

import numpy as np
import pytest

from common.images import Image
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import CameraAnnouncement
from services.camera.contract import CameraSettings
from services.camera.service import run
from services.camera.sources import FrameSource
from stack.config import Config
from tests.polling import wait_for
from tests.unit.heard import heard_cameras

CONFIG = Config()
CAMERA = CONFIG.stack.camera
KEYS = Keys(CONFIG.stack.prefix)
SETTINGS = CameraSettings(
    source="test:gated", rate_hz=50.0, mount_yaw_deg=90.0, hfov_deg=70.0, frame_id="left_cam"
)


class GatedSource:
    """``count`` images of ``width`` x ``height`` (forever when None), each once ``gate`` is
    set, then None: a device that stopped (when ``live``)."""

    def __init__(
        self, width: int, height: int, gate: threading.Event, *, count: int | None = None
    ) -> None:
        self.description = f"gated {width}x{height}"
        self.live = True
        self._image: Image = np.full((height, width, 3), 80, np.uint8)
        self._gate = gate
        self._left = count

    def read(self) -> Image | None:
        self._gate.wait()
        if self._left is not None:
            if self._left == 0:
                return None
            self._left -= 1
        return self._image

    def close(self) -> None:
        pass


def _announcement(width: int, height: int) -> CameraAnnouncement:
    return CameraAnnouncement(
        camera=CAMERA, width=width, height=height, rate_hz=50.0, mount_yaw_deg=90.0,
        hfov_deg=70.0, frame_id="left_cam", source="camera",
    )  # fmt: skip


def _said(a: CameraAnnouncement | None) -> CameraAnnouncement | None:
    """``a`` as heard, its ``zid`` checked (the camera process's session) and then cleared."""
    if a is None:
        return None
    assert a.zid.endswith("-camera"), a.zid
    return dataclasses.replace(a, zid="")


def _start(
    hub: MemoryHub, settings: CameraSettings, opener: Callable[..., FrameSource]
) -> tuple[threading.Event, threading.Thread]:
    stop = threading.Event()
    thread = threading.Thread(
        target=run,
        args=(CONFIG, CAMERA, settings, stop),
        kwargs={"bus": hub.join("camera", principal="camera"), "opener": opener},
        daemon=True,
    )
    thread.start()
    return stop, thread


@pytest.mark.parametrize("resize", [(0, 0), (16, 12)])
def test_the_camera_is_announced_sized_by_resize_or_its_first_frame_until_it_stops(
    resize: tuple[int, int],
) -> None:
    hub = MemoryHub()
    heard = heard_cameras(hub, KEYS)
    gate = threading.Event()
    settings = dataclasses.replace(SETTINGS, resize=resize)
    stop, thread = _start(hub, settings, lambda *a, **k: GatedSource(8, 6, gate))
    # Before any frame: the configured size, or 0x0 when the source's is not known yet.
    assert wait_for(lambda: _said(heard.get(CAMERA)), 10, "the camera's announcement") == (
        _announcement(*resize)
    )
    gate.set()
    size = resize if resize != (0, 0) else (8, 6)
    wait_for(
        lambda: _said(heard.get(CAMERA)) == _announcement(*size), 10, "the size of the first frame"
    )
    assert len(hub.tokens(KEYS.camera_announcements_of(CAMERA))) == 1  # the old one withdrawn
    stop.set()
    thread.join(10)
    assert not thread.is_alive()
    assert heard.current() == {}
    assert hub.tokens(KEYS.all_camera_announcements()) == []


def test_a_reopened_source_keeps_the_announcement_and_announces_its_new_size() -> None:
    hub = MemoryHub()
    seen: list[CameraAnnouncement | None] = []  # what is announced after each change
    heard = heard_cameras(hub, KEYS, on_change=lambda: seen.append(_said(heard.get(CAMERA))))
    open_gate, reopen_gate, opened = threading.Event(), threading.Event(), threading.Event()
    open_gate.set()
    sources = iter(
        [
            GatedSource(8, 6, open_gate, count=3),  # three frames, then the device is lost
            GatedSource(10, 4, reopen_gate),  # comes back (once the test lets it) bigger
        ]
    )

    def opener(*args: object, **kwargs: object) -> FrameSource:
        source = next(sources)
        if source.description.startswith("gated 10x4"):
            opened.set()
        return source

    settings = dataclasses.replace(SETTINGS, reopen_period_s=0.05)
    stop, thread = _start(hub, settings, opener)
    wait_for(opened.is_set, 10, "the lost device to be reopened")
    # Lost, and being reopened (its first frame awaited): still announced, at the old size.
    assert _said(heard.get(CAMERA)) == _announcement(8, 6)
    reopen_gate.set()
    wait_for(lambda: _said(heard.get(CAMERA)) == _announcement(10, 4), 10, "the reopened size")
    stop.set()
    thread.join(10)
    assert not thread.is_alive()
    first = seen.index(_announcement(0, 0))
    assert None not in seen[first:-1], seen  # never withdrawn before the stop
    assert seen[-1] is None and heard.current() == {}
