"""A profile chain on the real simulator: a further camera keeps what the base file says of it
(its mounting yaw and frame id) through profiles that change other fields of it, and renders
at the first camera's rate when no file gives it a rate of its own."""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np
import zenoh

from common.frames import frame_to_bgr
from common.messages import Frame
from tests.integration.conftest import Stack, wait_for, write_config

SIM_RATE_HZ = 4.0  # sim.camera_rate_hz: the first camera's rate in the simulator
CAMERA_RATE_HZ = 10.0  # [camera] rate_hz, which a further camera inherits


def test_a_three_level_profile_keeps_the_rear_camera_and_its_rate(tmp_path: Path) -> None:
    # The base: a rear camera turned round, with a frame id of its own, and a person behind
    # the robot (scenario "behind"), whom only a camera looking back sees.
    write_config(
        tmp_path,
        supervisor={"services": ["sim"]},
        sim={"scenario": "behind", "camera_rate_hz": SIM_RATE_HZ},
        camera={"rate_hz": CAMERA_RATE_HZ, "frame_id": "camera_front"},
        **{"cameras.rear": {"mount_yaw_deg": 180.0, "frame_id": "camera_rear"}},
    )
    # Two profiles, each changing one more field of the rear camera: fields the simulator does
    # not use, so that a rear camera reset to the front's view would render the front's pixels.
    (tmp_path / "middle.toml").write_text(
        'extends = "stack.toml"\n[cameras.rear]\nreopen_period_s = 2.0\n'
    )
    top = tmp_path / "robot.toml"
    top.write_text('extends = "middle.toml"\n[cameras.rear]\nloop = false\n')

    stack = Stack(top, tmp_path / "supervisor.log")
    frames: dict[str, list[Frame]] = {"front": [], "rear": []}
    lock = threading.Lock()

    def keep(camera: str) -> Callable[[zenoh.Sample], None]:
        def on_frame(sample: zenoh.Sample) -> None:
            with lock:
                frames[camera].append(Frame.decode(sample.payload.to_bytes()))

        return on_frame

    for camera in frames:
        stack.session.declare_subscriber(stack.keys.frame(camera), keep(camera))
    stack.wait_ready({"sim"})
    wait_for(lambda: len(frames["front"]) >= 12, 60, "12 frames of the front camera")
    with lock:
        front, rear = list(frames["front"]), list(frames["rear"])
    assert stack.stop() == 0, stack.log()

    # The rear camera is still the rear one: its frame id, and its view of the person.
    assert {f.header.frame_id for f in rear} == {"camera_rear"}
    assert {f.header.frame_id for f in front} == {"camera_front"}
    last_front, last_rear = frame_to_bgr(front[-1]), frame_to_bgr(rear[-1])
    assert last_front.shape == last_rear.shape
    same_view = np.array_equal(last_front, last_rear)
    assert not same_view, "the rear camera renders the front camera's view"
    # Both are rendered on one clock at the first camera's rate (the simulator renders both
    # in the same pass, so the counts differ by a frame at most at the window's edges).
    n_front, n_rear = len(front), len(rear)
    assert abs(n_rear - n_front) <= 2, f"{n_front} front frames, {n_rear} rear frames"
