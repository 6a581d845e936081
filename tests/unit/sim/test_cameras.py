"""Several cameras in the simulator: each renders the same world from its own mounting yaw, at
its own size and rate (services/sim/cameras.py, simworld/render.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.messages import GroundTruth, Header
from common.settings import StackSettings
from services.camera.contract import CameraSettings
from services.controller.contract import ControllerSettings
from services.sim.cameras import sim_cameras
from services.sim.contract import SimSettings
from simworld.render import CameraSpec, render
from simworld.scenarios import SCENARIOS, person
from simworld.world import Robot, World
from stack.config import Config
from tools.scenarios.score import ScenarioLog, score

FRONT = CameraSpec(width=320, height=240, hfov_deg=60.0, height_m=0.6)
REAR = CameraSpec(width=320, height=240, hfov_deg=60.0, height_m=0.6, mount_yaw_deg=180.0)


def _changed_columns(world: World, spec: CameraSpec) -> np.ndarray:
    """The image columns where ``world`` differs from the empty world, as that camera sees."""
    empty = render(World(Robot(theta=world.robot.theta)), spec)
    return np.nonzero(np.any(render(world, spec) != empty, axis=(0, 2)))[0]


def test_a_person_behind_the_robot_is_seen_by_the_rear_camera_alone() -> None:
    behind = World(Robot(), targets=[person("a", (0, -3.0, 0.0))])
    assert _changed_columns(behind, FRONT).size == 0
    cols = _changed_columns(behind, REAR)
    assert cols.size > 0 and cols.mean() == pytest.approx(160, abs=3)  # dead centre


def test_a_person_ahead_is_seen_by_the_front_camera_alone() -> None:
    ahead = World(Robot(), targets=[person("a", (0, 3.0, 0.0))])
    assert _changed_columns(ahead, FRONT).size > 0
    assert _changed_columns(ahead, REAR).size == 0


def test_the_rear_camera_mirrors_left_and_right() -> None:
    # Behind and to the robot's left (+y): the rear camera looks the other way, so it sees the
    # person on the right half of its image, as a real rear camera would.
    left_behind = World(Robot(), targets=[person("a", (0, -3.0, 0.8))])
    assert _changed_columns(left_behind, REAR).mean() > 160 + 20


def test_the_camera_turns_with_the_robot() -> None:
    # The robot turned round (theta = 180 deg): the person behind its start is now ahead.
    turned = World(Robot(theta=math.pi), targets=[person("a", (0, -3.0, 0.0))])
    assert _changed_columns(turned, FRONT).size > 0
    assert _changed_columns(turned, REAR).size == 0


def _config(*cameras: tuple[str, CameraSettings]) -> Config:
    return Config(
        stack=StackSettings(camera="front"),
        camera=CameraSettings(rate_hz=10.0, resize=(0, 0), frame_id="cam_front"),
        cameras=cameras,
        sim=SimSettings(width=640, height=480, camera_rate_hz=5.0, camera_height_m=0.7),
    )


def test_one_camera_renders_as_the_simulator_always_did() -> None:
    (front,) = sim_cameras(_config())
    assert (front.name, front.rate_hz, front.frame_id) == ("front", 5.0, "cam_front")
    assert front.spec == CameraSpec(640, 480, 60.0, 0.7, 0.0)


def test_further_cameras_have_their_own_rate_size_view_and_yaw() -> None:
    rear = CameraSettings(rate_hz=2.0, resize=(320, 240), hfov_deg=90.0, mount_yaw_deg=180.0,
                          frame_id="cam_rear", jpeg_quality=80)  # fmt: skip
    left = CameraSettings(rate_hz=3.0, mount_yaw_deg=90.0)
    front, r, lf = sim_cameras(_config(("rear", rear), ("left", left)))
    assert front.rate_hz == 5.0  # the first: sim.camera_rate_hz
    assert (r.name, r.rate_hz, r.frame_id, r.jpeg_quality) == ("rear", 2.0, "cam_rear", 80)
    assert r.spec == CameraSpec(320, 240, 90.0, 0.7, 180.0)
    # No resize: the simulator's size.
    assert (lf.rate_hz, lf.spec.width, lf.spec.height, lf.spec.mount_yaw_deg) == (3.0, 640, 480, 90)


def test_a_further_camera_that_sets_no_rate_renders_at_the_first_camera_s_rate() -> None:
    # [camera] rate_hz 10, sim.camera_rate_hz 5: the first camera is rendered at 5 Hz, and so
    # is a further camera that does not state a rate of its own (it has [camera]'s).
    rear = CameraSettings(rate_hz=10.0, mount_yaw_deg=180.0, frame_id="cam_rear")
    left = CameraSettings(rate_hz=2.0, mount_yaw_deg=90.0, frame_id="cam_left")
    front, r, lf = sim_cameras(_config(("rear", rear), ("left", left)))
    assert (front.rate_hz, r.rate_hz, lf.rate_hz) == (5.0, 5.0, 2.0)


HDR = Header(stamp_ns=1, frame_id="world", seq=1, source="sim")


def _truth(t: float, x: float, theta: float) -> GroundTruth:
    return GroundTruth(
        header=HDR,
        sim_time_s=t,
        robot=(x, 0.0, theta),
        targets_xy=np.array([[-4.0, 0.5]]),
        target_names=("person",),
        target_ids=("alice",),
    )


def test_behind_passes_only_when_the_robot_turned_round_and_reached_the_person() -> None:
    sc = SCENARIOS["behind"]
    assert sc.cameras["rear"]["mount_yaw_deg"] == 180.0 and sc.must_face
    world = sc.build()
    # The person stands behind: the front camera cannot see them, the rear one can.
    front = CameraSpec(mount_yaw_deg=0.0)
    rear = CameraSpec(mount_yaw_deg=sc.cameras["rear"]["mount_yaw_deg"])
    assert _changed_columns(world, front).size == 0 and _changed_columns(world, rear).size > 0
    s = ControllerSettings(mode="follow")
    facing = math.atan2(0.5, -4.0 + 2.7)
    turned = [_truth(0.5, 0.0, 0.0), _truth(10.0, -2.7, facing)]
    result = score(sc, ScenarioLog(truths=turned), world, s, 60.0)
    assert result["checks"]["turned to face the target"], result
    assert result["success"], result
    # At the same spot but backed up to it, still facing away: not a pass.
    backed = [_truth(0.5, 0.0, 0.0), _truth(10.0, -2.7, 0.0)]
    result = score(sc, ScenarioLog(truths=backed), world, s, 60.0)
    assert abs(result["final_bearing_deg"]) > 150
    assert not result["checks"]["turned to face the target"] and not result["success"]
