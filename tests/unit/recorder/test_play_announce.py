"""``zstack play`` announces each camera whose frames it plays (services/recorder/play.py):
the recorded size and frame id, the recorded rate times the play's speed, the camera's
mounting from the config; on a MemoryHub, from a recording written here."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from common.camera_announce import CameraAnnouncements
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import CameraAnnouncement, Frame, Header
from services.camera.contract import CameraSettings
from services.recorder.channels import Translator
from services.recorder.contract import RecorderSettings
from services.recorder.play import ANNOUNCED_SOURCE, announce_played, recorded_cameras
from services.recorder.writer import McapFile
from stack.config import Config
from tests.unit.heard import heard_cameras

CONFIG = Config(
    camera=CameraSettings(rate_hz=7.0),
    cameras=(
        ("rear", CameraSettings(rate_hz=3.0, mount_yaw_deg=180.0, hfov_deg=90.0)),
        ("left", CameraSettings(mount_yaw_deg=90.0)),  # configured, not in the recording
    ),
)
KEYS = Keys(CONFIG.stack.prefix)
FRONT = CONFIG.stack.camera
T0 = 1_700_000_000 * 10**9


def _frame(seq: int, width: int, height: int, frame_id: str) -> Frame:
    header = Header(stamp_ns=T0 + seq, frame_id=frame_id, seq=seq, source="sim")
    pixels = np.zeros(width * height * 3, np.uint8)
    return Frame(header=header, encoding="bgr8", width=width, height=height, data=pixels.tobytes())


def _recording(path: Path) -> list[str]:
    """Front: 5 frames of 64x48 at 10 Hz; rear: one of 32x24."""
    out = McapFile(path, RecorderSettings(chunk_size_kb=16, flush_period_s=60.0))
    translator = Translator(CONFIG.ros2, FRONT)
    for seq in range(5):
        frame = _frame(seq, 64, 48, "front_optical")
        for entry in translator.entries(KEYS.frame(FRONT), frame):
            out.add(entry, T0 + seq * 100_000_000)
    for entry in translator.entries(KEYS.frame("rear"), _frame(9, 32, 24, "rear_optical")):
        out.add(entry, T0 + 50_000_000)
    out.close()
    return ["/camera/rgb/image_raw", "/rear/camera/rgb/image_raw"]


def test_each_played_camera_is_announced_as_recorded_until_the_play_ends(tmp_path: Path) -> None:
    topics = _recording(tmp_path / "r.mcap")
    recorded = recorded_cameras(CONFIG, tmp_path / "r.mcap", topics)
    assert set(recorded) == {FRONT, "rear"}
    hub = MemoryHub()
    heard = heard_cameras(hub, KEYS)
    bus = hub.join("play")  # the player's session, named in its announcements
    with CameraAnnouncements(bus, KEYS, ANNOUNCED_SOURCE) as announcements:
        announce_played(CONFIG, announcements, recorded, rate=2.0)
        assert heard.current() == {
            # 5 frames over 0.4 s: 10 Hz, played twice as fast
            FRONT: CameraAnnouncement(
                camera=FRONT, width=64, height=48, rate_hz=20.0, mount_yaw_deg=0.0,
                hfov_deg=60.0, frame_id="front_optical", source="play", zid=bus.zid,
            ),
            # one frame: no recorded rate, so its configured one
            "rear": CameraAnnouncement(
                camera="rear", width=32, height=24, rate_hz=6.0, mount_yaw_deg=180.0,
                hfov_deg=90.0, frame_id="rear_optical", source="play", zid=bus.zid,
            ),
        }  # fmt: skip
        assert len(hub.tokens(KEYS.all_camera_announcements())) == 2
    assert heard.current() == {}  # the play ended


def test_only_the_cameras_played_are_announced(tmp_path: Path) -> None:
    topics = _recording(tmp_path / "r.mcap")
    # Only the rear topic chosen; a one-camera stack plays it as its own camera.
    assert set(recorded_cameras(CONFIG, tmp_path / "r.mcap", topics[1:])) == {"rear"}
    only_front = recorded_cameras(Config(), tmp_path / "r.mcap", topics)
    assert list(only_front) == [FRONT] and only_front[FRONT].frames == 6
