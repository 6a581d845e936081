"""The viewer marks the controller's locked track only on the camera that sees it: each
camera's tracker numbers its own tracks, so the same id on another camera is another object."""

from __future__ import annotations

from dataclasses import replace

import foxglove

from common.messages import ControllerStatus, Header
from common.node import Tally
from services.viewer.channels import Channels
from services.viewer.service import Viewer
from stack.config import Config


def _viewer() -> Viewer:
    base = Config()
    config = replace(base, cameras=(("rear", replace(base.camera, frame_id="rear")),))
    return Viewer(
        Tally("viewer", config), Channels(foxglove.Context(), list(config.all_cameras)), config
    )


def _status(track_id: int, camera: str) -> bytes:
    return ControllerStatus(
        header=Header(stamp_ns=1, frame_id="base_link", seq=1, source="controller"),
        mode="follow",
        target="person",
        state="following",
        track_id=track_id,
        camera=camera,
    ).encode()


def test_the_lock_is_marked_on_its_own_camera_only() -> None:
    viewer = _viewer()
    first = next(iter(viewer.cameras))
    assert viewer.locked_on(first) == -1 and viewer.locked_on("rear") == -1
    viewer.on_status(_status(3, "rear"))
    assert viewer.locked_on("rear") == 3
    assert viewer.locked_on(first) == -1  # track 3 of the front camera is someone else
    viewer.on_status(_status(7, first))
    assert (viewer.locked_on(first), viewer.locked_on("rear")) == (7, -1)


def test_a_status_naming_no_camera_locks_on_the_first() -> None:
    viewer = _viewer()
    viewer.on_status(_status(5, ""))
    assert viewer.locked_on(next(iter(viewer.cameras))) == 5
    assert viewer.locked_on("rear") == -1
