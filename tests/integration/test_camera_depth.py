"""A recorded RGB-D camera as a real process under the supervisor: a colour folder and a folder of
16-bit depth PNGs give one DepthFrame per colour frame with that frame's header, the camera is
announced with depth and its mounting, a bad depth PNG is counted and skipped; and an RGB-D
camera whose SDK is not installed is one line."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from common.announce import Announced
from common.images import load_sample
from common.messages import CameraAnnouncement, DepthFrame, Frame, ServiceCounters
from common.zenoh_bus import ZenohBus
from services.camera import contract
from tests.integration.conftest import REPO, Stack, wait_for, write_config

pytestmark = pytest.mark.integration


def _rgbd(tmp_path: Path) -> tuple[Path, Path]:
    """Two photos and their depth PNGs, and a third photo whose depth PNG is 8-bit (bad)."""
    rgb, depth = tmp_path / "rgb", tmp_path / "depth"
    rgb.mkdir()
    depth.mkdir()
    for i, name in enumerate(("chelsea", "coffee", "astronaut")):
        assert cv2.imwrite(str(rgb / f"{i:03d}.jpg"), cv2.resize(load_sample(name), (96, 72)))
        mm = np.full((72, 96), 1500 + 500 * i, np.uint16)
        assert cv2.imwrite(str(depth / f"{i:03d}.png"), mm if i < 2 else np.uint8(mm // 100))
    return rgb, depth


def test_a_depth_folder_camera_publishes_depth_with_its_frames_headers(
    make_stack: Callable[..., Stack], tmp_path: Path
) -> None:
    rgb, depth = _rgbd(tmp_path)
    stack = make_stack(
        supervisor={"services": ["camera"]},
        camera={
            "source": str(rgb),
            "depth_source": str(depth),
            "rate_hz": 10.0,
            "mount_height_m": 0.35,
            "mount_x_m": 0.12,
            "frame_id": "rgbd",
        },
    )
    keys, camera = stack.keys, stack.config.stack.camera
    heard: Announced[CameraAnnouncement] = Announced(
        ZenohBus(stack.session),  # closed with the stack's session
        keys.all_camera_announcements(),
        keys.camera_announcement_parts,
        CameraAnnouncement.decode,
        lambda a: a.camera,
    )
    _frames_sub, frames = stack.subscribe(keys.frame(camera))
    _depth_sub, depths = stack.subscribe(keys.depth(camera))
    _counters_sub, counters = stack.subscribe(keys.counters("camera"))

    def bad_counted() -> bool:
        return any(ServiceCounters.decode(c).counters.get(contract.BAD_DEPTH, 0) for c in counters)

    wait_for(lambda: len(depths) >= 4 and bad_counted(), 60, lambda: f"depth:\n{stack.log()}")
    announced = heard.get(camera)
    assert announced is not None and announced.depth, announced
    assert (announced.mount_height_m, announced.mount_x_m) == (0.35, 0.12)
    assert stack.stop() == 0

    colour = {f.header.seq: f for f in map(Frame.decode, list(frames))}
    by_seq = {d.header.seq: d for d in map(DepthFrame.decode, list(depths))}
    assert len(by_seq) == len(depths) >= 4
    # The folder in name order from seq 1: 000 (1.5 m), 001 (2 m), 002 (its PNG 8-bit: none).
    for seq, d in by_seq.items():
        assert (seq - 1) % 3 != 2, seq
        assert np.unique(np.frombuffer(d.data, "<u2")).tolist() == [1500 + 500 * ((seq - 1) % 3)]
        assert (d.width, d.height, d.header.frame_id) == (96, 72, "rgbd")
        if seq in colour:  # else its colour frame came after the test stopped looking
            assert d.header == colour[seq].header
    assert {(s - 1) % 3 for s in colour if s not in by_seq and s < max(by_seq)} == {2}


@pytest.mark.skipif(
    importlib.util.find_spec("pyrealsense2") is not None, reason="pyrealsense2 is installed here"
)
def test_a_realsense_camera_without_pyrealsense2_is_one_line(tmp_path: Path) -> None:
    config = write_config(tmp_path)
    done = subprocess.run(
        [sys.executable, "-m", "services.camera", "serve", "--config", str(config),
         "--source", "realsense:"],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        "camera: error: camera source 'realsense:': pyrealsense2 is not installed; install the "
        "realsense extra: pip install '.[realsense]'"
    ]


def test_a_missing_depth_folder_is_one_line(tmp_path: Path) -> None:
    rgb, _ = _rgbd(tmp_path)
    missing = tmp_path / "no_depth_here"
    config = write_config(tmp_path, camera={"source": str(rgb), "depth_source": str(missing)})
    done = subprocess.run(
        [sys.executable, "-m", "services.camera", "serve", "--config", str(config)],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        f"camera: error: camera.depth_source '{missing}': no such folder"
    ]
