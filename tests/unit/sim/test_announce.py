"""The simulator announces each camera it renders onto the stack's keys, while it runs: run
in-process on a MemoryHub."""

from __future__ import annotations

import threading

from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import CameraAnnouncement
from services.camera.contract import CameraSettings
from services.sim.contract import SimSettings
from services.sim.service import run
from stack.config import Config
from tests.polling import wait_for
from tests.unit.heard import heard_cameras

CONFIG = Config(
    camera=CameraSettings(hfov_deg=80.0, frame_id="front_cam"),
    cameras=(
        ("rear", CameraSettings(mount_yaw_deg=180.0, frame_id="rear", resize=(32, 24), rate_hz=3)),
    ),
    sim=SimSettings(width=64, height=48, camera_rate_hz=4.0, physics_hz=20.0),
)
KEYS = Keys(CONFIG.stack.prefix)


def test_each_simulated_camera_is_announced_while_the_simulator_runs() -> None:
    hub = MemoryHub()
    heard = heard_cameras(hub, KEYS)
    frames: list[str] = []
    hub.join("watcher").subscribe(KEYS.all_frames(), lambda s: frames.append(s.key))
    stop = threading.Event()
    bus = hub.join("sim")  # the simulator's session: its announcements name it (zid)
    sim = threading.Thread(target=run, args=(CONFIG, stop), kwargs={"bus": bus}, daemon=True)
    sim.start()
    wait_for(lambda: len(heard.current()) == 2, 20, "both cameras' announcements")
    front = CONFIG.stack.camera
    assert heard.current() == {
        front: CameraAnnouncement(
            camera=front, width=64, height=48, rate_hz=4.0, mount_yaw_deg=0.0, hfov_deg=80.0,
            frame_id="front_cam", source="sim", zid=bus.zid,
        ),
        "rear": CameraAnnouncement(
            camera="rear", width=32, height=24, rate_hz=3.0, mount_yaw_deg=180.0, hfov_deg=60.0,
            frame_id="rear", source="sim", zid=bus.zid,
        ),
    }  # fmt: skip
    # Announced as their frames come, on the keys announced.
    wait_for(lambda: {KEYS.frame(front), KEYS.frame("rear")} <= set(frames), 20, "both cameras")
    stop.set()
    sim.join(20)
    assert not sim.is_alive()
    assert heard.current() == {}
    assert hub.tokens(KEYS.all_camera_announcements()) == []
