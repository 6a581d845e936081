"""The ROS 2 bridge announces each camera it bridges into the stack: at start with its
configured rate, mounting and field of view, then the size and frame id of its first image.
The bridge's inbound images are decoded and put on a MemoryHub in-process; the ROS side is
stood in for by the CDR an rmw_zenoh publisher would send."""

from __future__ import annotations

import dataclasses

import numpy as np

from common.camera_announce import CameraAnnouncements
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import CameraAnnouncement
from common.node import Node
from rosmsg.convert import ros_header
from rosmsg.distro import RosDistro
from rosmsg.images import IMAGE
from services.camera.contract import CameraSettings
from services.ros2.service import ANNOUNCED_SOURCE, RosInbound, announce_bridged
from stack.config import Config
from tests.unit.heard import heard_cameras
from tests.unit.rosmsg.test_images import STAMP_NS, ros_image

CONFIG = Config(
    camera=CameraSettings(rate_hz=15.0, hfov_deg=87.0),
    cameras=(
        (
            "rear",
            CameraSettings(
                rate_hz=6.0,
                mount_yaw_deg=180.0,
                frame_id="rear",
                mount_height_m=0.4,
                mount_x_m=-0.2,
                mount_y_m=0.05,
            ),
        ),
    ),
)
KEYS = Keys(CONFIG.stack.prefix)
FRONT = CONFIG.stack.camera


def _announced(camera: str, **changes: object) -> CameraAnnouncement:
    fields: dict[str, object] = {
        FRONT: {"rate_hz": 15.0, "hfov_deg": 87.0, "frame_id": "camera"},
        "rear": {
            "rate_hz": 6.0,
            "mount_yaw_deg": 180.0,
            "frame_id": "rear",
            "mount_height_m": 0.4,
            "mount_x_m": -0.2,
            "mount_y_m": 0.05,
        },
    }[camera] | changes  # type: ignore[operator]
    return CameraAnnouncement(camera=camera, source="ros2", **fields)  # type: ignore[arg-type]


def test_each_bridged_camera_is_announced_then_sized_by_its_first_image() -> None:
    hub = MemoryHub()
    heard = heard_cameras(hub, KEYS)
    node = Node("ros2", CONFIG, bus=hub.join("ros2"))
    with CameraAnnouncements(node.bus, node.keys, ANNOUNCED_SOURCE) as announcements:
        told = announce_bridged(CONFIG, announcements)
        zid = node.bus.zid  # the bridge's session, named in its announcements
        assert heard.current() == {
            FRONT: _announced(FRONT, zid=zid),
            "rear": _announced("rear", zid=zid),
        }
        put: list[bytes] = []
        rear_in = RosInbound(CONFIG, node, IMAGE, "/rear/camera/rgb/image_raw", put.append,
                             told["rear"])  # fmt: skip
        rear_in.on_payload("k", memoryview(b"\x00\x01garbage"))  # counted, dropped, unsized
        assert heard.get("rear") == _announced("rear", zid=zid)
        image = ros_image(
            RosDistro.JAZZY, header=ros_header(RosDistro.JAZZY, STAMP_NS, "rear_optical"),
            height=4, width=5, step=15, data=np.zeros(60, np.uint8),
        )  # fmt: skip
        rear_in.on_payload("k", memoryview(image))
        assert len(put) == 1
        assert heard.get("rear") == _announced(
            "rear", width=5, height=4, frame_id="rear_optical", zid=zid
        )
        assert heard.get(FRONT) == _announced(FRONT, zid=zid)  # not its image
        assert len(hub.tokens(KEYS.camera_announcements_of("rear"))) == 1
    assert heard.current() == {}  # the bridge stopped: every announcement goes
    node.close()


def test_a_bridge_that_takes_no_images_announces_no_camera() -> None:
    hub = MemoryHub()
    heard = heard_cameras(hub, KEYS)
    config = dataclasses.replace(CONFIG, ros2=dataclasses.replace(CONFIG.ros2, image_in=False))
    with CameraAnnouncements(hub.join("ros2"), KEYS, ANNOUNCED_SOURCE) as announcements:
        assert announce_bridged(config, announcements) == {}
        assert heard.current() == {}


def test_with_depth_in_each_bridged_camera_is_announced_as_a_depth_camera() -> None:
    hub = MemoryHub()
    heard = heard_cameras(hub, KEYS)
    config = dataclasses.replace(CONFIG, ros2=dataclasses.replace(CONFIG.ros2, depth_in=True))
    bus = hub.join("ros2")
    with CameraAnnouncements(bus, KEYS, ANNOUNCED_SOURCE) as announcements:
        announce_bridged(config, announcements)
        assert heard.current() == {
            FRONT: _announced(FRONT, depth=True, zid=bus.zid),
            "rear": _announced("rear", depth=True, zid=bus.zid),
        }
