"""The controller's cameras are those announced on the bus (common/announce.py), in-process
(tests/unit/controller/rig.py): a camera announced at run time is used, a withdrawn one is
ignored (and a stop when it held the target), its geometry is the announced one, and a camera
nobody announces never moves the robot."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from services.camera.contract import CameraSettings
from services.controller import contract
from tests.unit.controller.rig import Rig, people

REAR = CameraSettings(mount_yaw_deg=180.0)


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[Rig]:
    r = Rig(tmp_path)  # the front camera announced
    yield r
    r.close()


def test_detections_of_a_camera_nobody_announces_never_move_the_robot(tmp_path: Path) -> None:
    rig = Rig(tmp_path, announced=False)
    try:
        for n in range(1, 21):
            rig.scan()
            rig.detections("front")  # a centred person, the way clear: would drive
            rig.detections("ghost")
            twist, status = rig.tick()
            assert twist.is_zero and status.state == "stale", status
            assert status.reason == "no camera announced"
            assert rig.counters[contract.DETECTIONS_UNANNOUNCED] == 2 * n
            rig.clock.advance(0.05)
        assert "detections_in" not in rig.counters
        # The control: the same detections from the camera once announced drive it.
        rig.announce("front")
        rig.detections("front")
        twist, status = rig.tick()
        assert status.state == "tracking" and twist.linear[0] > 0, status
    finally:
        rig.close()


def test_an_unannounced_camera_beside_an_announced_one_is_ignored(rig: Rig) -> None:
    for _ in range(10):
        rig.scan()
        rig.detections("front", people(rig.header(), n=0))  # nobody in front
        rig.detections("rear")  # a person seen by a camera nobody announced
        twist, status = rig.tick()
        assert twist.is_zero and status.state == "searching", status
        assert status.stale_cameras == ()  # not one of the controller's cameras at all
        rig.clock.advance(0.05)
    assert rig.counters[contract.DETECTIONS_UNANNOUNCED] == 10


def test_a_camera_announced_at_run_time_is_used(rig: Rig) -> None:
    rig.scan()
    rig.detections("rear")
    assert rig.tick()[0].is_zero
    rig.announce("rear", REAR)
    rig.clock.advance(0.05)
    rig.scan()
    rig.detections("front", people(rig.header(), n=0))
    rig.detections("rear")  # centred in the rear camera: the target is behind
    twist, status = rig.tick()
    assert status.state == "turning" and status.camera == "rear", status
    assert twist.angular[2] > 0 and twist.linear[0] == 0.0
    assert rig.counters["detections_in.rear"] == 1


@pytest.mark.parametrize("again", [False, True], ids=["withdrawn", "withdrawn-and-back"])
def test_the_targets_camera_withdrawn_is_a_stop(rig: Rig, again: bool) -> None:
    rig.announce("rear", REAR)
    rig.scan()
    rig.detections("front", people(rig.header(), n=0))
    rig.detections("rear")
    twist, status = rig.tick()
    assert status.camera == "rear" and not twist.is_zero, status
    rig.clock.advance(0.05)
    rig.withdraw("rear")  # its detections, still fresh, are no longer used
    if again:
        rig.announce("rear", REAR)  # a restarted source, between two ticks
    rig.scan()
    rig.detections("front", people(rig.header(), n=0))
    twist, status = rig.tick()
    assert twist.is_zero and status.state == "stale", status
    assert status.reason == "the target's camera rear is no longer announced"
    if not again:
        # From now on the rear camera's detections are counted and ignored.
        rig.clock.advance(0.05)
        rig.scan()
        rig.detections("front", people(rig.header(), n=0))
        rig.detections("rear")
        twist, status = rig.tick()
        assert twist.is_zero and status.state == "searching", status
        assert rig.counters[contract.DETECTIONS_UNANNOUNCED] == 1


def test_another_camera_withdrawn_leaves_the_target_alone(rig: Rig) -> None:
    rig.announce("rear", REAR)
    rig.scan()
    rig.detections("front")
    rig.detections("rear", people(rig.header(), n=0))
    assert rig.tick()[1].state == "tracking"
    rig.withdraw("rear")
    rig.clock.advance(0.05)
    rig.scan()
    rig.detections("front")
    twist, status = rig.tick()
    assert status.state == "tracking" and twist.linear[0] > 0, status
    assert status.stale_cameras == ()  # the rear camera is gone, not stale


@pytest.mark.parametrize("yaw,sign", [(90.0, 1.0), (-90.0, -1.0)])
def test_the_announced_yaw_turns_the_bearing(rig: Rig, yaw: float, sign: float) -> None:
    rig.scan()
    rig.detections()  # centred in the front camera: straight ahead
    twist, status = rig.tick()
    assert status.state == "tracking" and twist.angular[2] == 0.0, status
    rig.announce("front", mount_yaw_deg=yaw)  # the same camera, now looking sideways
    rig.clock.advance(0.05)
    rig.scan()
    rig.detections()
    twist, status = rig.tick()
    # Braking at the acceleration limit from the one tick's speed: to zero, but for rounding.
    assert status.state == "turning" and twist.linear[0] == pytest.approx(0.0, abs=1e-9), status
    assert twist.angular[2] * sign > 0, twist
    assert status.reason == f"bearing {yaw:+.1f} deg"


def test_a_garbage_announcement_is_counted_and_adds_no_camera(tmp_path: Path) -> None:
    rig = Rig(tmp_path, announced=False)
    try:
        rogue = rig.hub.join("rogue")
        rogue.declare_token(rig.keys.camera_announcement("front", "bm90LWFuLWFubm91bmNlbWVudA"))
        rig.scan()
        rig.detections("front")
        twist, status = rig.tick()
        assert twist.is_zero and status.reason == "no camera announced", status
        c = rig.counters
        assert c["bad_input.camera_announcement"] == 1, c
        assert c[contract.DETECTIONS_UNANNOUNCED] == 1, c
    finally:
        rig.close()
