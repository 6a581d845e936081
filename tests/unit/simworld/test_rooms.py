"""The rooms and the crowds (issue 41): each world builds with the people, walls and hazards its
scenario names, alice's way is clear of them, and the occlusions happen by geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.controller.contract import ControllerSettings
from simworld import crowds, rooms
from simworld.body import body_for
from simworld.depth import targets_in_camera
from simworld.laser import LaserSpec
from simworld.render import CameraSpec
from simworld.scenarios import CROWD_SCENARIOS, ROOM_SCENARIOS, SCENARIOS
from simworld.world import Material, Target, World

SPEC = CameraSpec(width=320, height=240, hfov_deg=60.0, height_m=0.6)
LASER_PLANE_M = LaserSpec().height_m
SAFE = ControllerSettings().safety_distance_m
NEW = [sc.name for sc in (*ROOM_SCENARIOS, *CROWD_SCENARIOS)]


def _alice(world: World) -> Target:
    return next(t for t in world.targets if t.id == "alice")


def _times(end_s: float, step_s: float = 0.1) -> np.ndarray:
    return np.arange(0.0, end_s + step_s, step_s)


def test_the_rooms_and_crowds_are_scenarios_of_three_to_six_different_people() -> None:
    assert NEW == [
        "rooms", "step_room", "passing", "swap", "pillar", "fast_turn", "crowd", "handover",
    ]  # fmt: skip
    for name in NEW:
        sc = SCENARIOS[name]
        world = sc.build()
        ids = [t.id for t in world.targets]
        assert sc.followed == "alice" and "alice" in ids
        assert 3 <= len(ids) <= 6 and len(set(ids)) == len(ids)
        bodies = [t.body for t in world.targets]
        assert all(t.body is not None and t.body == body_for(t.id) for t in world.targets)
        assert len({(b.height_m, b.shoulder_m) for b in bodies if b is not None}) == len(ids)
        # Never nearer than the safety distance at the start: the run judges the robot.
        assert world.clearance() + world.robot.radius >= SAFE
    assert len(crowds.crowd().targets) == 5


@pytest.mark.parametrize("name", NEW)
def test_alice_ends_apart_from_everyone_and_her_way_is_clear(name: str) -> None:
    sc = SCENARIOS[name]
    world = sc.build()
    alice = _alice(world)
    end = np.array(alice.position(sc.settle_from_s))
    others = [t for t in world.targets if t is not alice]
    assert min(np.hypot(*(np.array(t.position(sc.duration_s)) - end)) for t in others) >= (
        crowds.APART_M
    )
    assert alice.position(sc.duration_s) == alice.position(sc.settle_from_s)  # she stands
    # Where she walks, a robot's centre keeps the safety distance and its radius from every
    # obstacle and wall: the way behind her is clear (a drop she walks down is not). In
    # pillar she walks behind the pillar: the robot must not follow her there but go round.
    if name == "pillar":
        return
    margin = SAFE + world.robot.radius
    for t in _times(sc.settle_from_s):
        x, y = alice.position(float(t))
        near = [math.hypot(o.x - x, o.y - y) - o.radius for o in world.obstacles]
        near += [w.distance(x, y) for w in world.walls]
        assert min(near, default=math.inf) >= margin, (name, t, x, y)


def test_the_rooms_hold_every_hazard_kind_among_walls_off_alices_path() -> None:
    for build in (rooms.rooms, rooms.step_room):
        world = build()
        assert len(world.walls) >= 6 and world.drops
        obs = world.obstacles
        assert any(o.height_m < LASER_PLANE_M for o in obs)  # a low box
        assert any(o.radius <= 0.05 for o in obs)  # a thin pole
        assert any(o.material == Material.MIRROR for o in obs)
        assert any(w.material == Material.GLASS for w in world.walls)
    assert any(o.material == Material.DARK and o.radius > 0.05 for o in rooms.rooms().obstacles)
    # The doorway: its jambs are DOOR_WIDTH_M apart and alice walks through its middle.
    world = rooms.rooms()
    jambs = [w for w in world.walls if w.x0 == w.x1 == rooms.ROOMS_DOOR_X]
    assert (
        sorted(abs(w.y1 if abs(w.y0) == rooms.ROOM_HALF_M else w.y0) for w in jambs)
        == [rooms.DOOR_WIDTH_M / 2] * 2
    )


def test_the_rooms_walls_are_seen_by_the_laser_and_hide_what_is_behind() -> None:
    world = rooms.rooms()
    assert len(world.laser_walls(LASER_PLANE_M)) == len(world.walls) - 1  # not the glass
    # From the start, carol in the second room is behind the partition, out of sight.
    assert "carol" not in [t[0] for t in targets_in_camera(world, SPEC)]
    assert "alice" in [t[0] for t in targets_in_camera(world, SPEC)]


def test_step_room_alice_ends_down_the_step_where_the_robot_must_not_follow() -> None:
    sc = SCENARIOS["step_room"]
    world = sc.build()
    (drop,) = world.drops
    x, y = _alice(world).position(sc.duration_s)
    assert drop.distance(x, y) < -1.0  # 1.5 m beyond the edge
    assert not sc.must_reach  # a follower wants to go on: stopping at the edge is the pass
    x, y = _alice(rooms.rooms()).position(60.0)
    assert rooms.rooms().drops[0].distance(x, y) > 0.5  # in rooms the step is behind her


def test_pillar_hides_alice_for_one_to_two_seconds() -> None:
    world = crowds.pillar()
    alice = world.targets[0]
    for rx in (0.0, 1.5, 3.0):  # from the start, or a robot that has come on 3 m
        world.robot.x = rx
        hidden = 0
        for t in _times(crowds.PILLAR_END_S, 0.05):
            world.t = float(t)
            ax, ay = alice.position(world.t)
            world.robot.theta = math.atan2(ay, ax - rx)  # facing her
            hidden += "alice" not in [tg[0] for tg in targets_in_camera(world, SPEC)]
        assert 1.0 <= hidden * 0.05 <= 2.0, (rx, hidden * 0.05)


def test_passing_bob_walks_between_the_robot_and_alice() -> None:
    world = crowds.passing()
    alice, bob = world.targets[0], world.targets[1]
    crossed = [
        t
        for t in _times(10.0)
        if abs(bob.position(float(t))[1]) < 0.1
        and bob.position(float(t))[0] < alice.position(float(t))[0]
    ]
    assert crossed and 3.0 < crossed[0] < 5.0


def test_swap_alice_and_bob_change_sides_with_bob_in_front() -> None:
    world = crowds.swap()
    alice, bob = world.targets[0], world.targets[1]
    assert alice.position(0.0)[1] < 0 < bob.position(0.0)[1]
    assert bob.position(30.0)[1] < 0 < alice.position(30.0)[1]
    mid = 4.0  # both cross y = 0 here, bob nearer the robot
    assert abs(alice.position(mid)[1]) < 0.1 and abs(bob.position(mid)[1]) < 0.1
    assert bob.position(mid)[0] < alice.position(mid)[0] - 2 * world.targets[0].radius


def test_fast_turn_alice_sweeps_out_of_the_view_faster_than_thirty_degrees_a_second() -> None:
    alice = crowds.fast_turn().targets[0]
    t0, t1 = crowds.FAST_START_S, crowds.FAST_START_S + 3.7 / crowds.FAST_SPEED_MPS
    b0 = math.degrees(math.atan2(*reversed(alice.position(t0))))
    b1 = math.degrees(math.atan2(*reversed(alice.position(t1))))
    assert b0 < -20 and b1 > 30  # from the right of the view to beyond its left edge
    assert (b1 - b0) / (t1 - t0) > 30


def test_handover_alice_leaves_the_front_view_for_the_left_one_near_bob() -> None:
    """From the robot's start: alice in the front camera's view (within 30 deg) before she
    strides, in the left one's (60 to 120 deg) after, sweeping faster than 30 deg/s; bob in the
    left one's, within the hand-over gate (20 deg) of her bearing as she comes into it."""
    alice, bob, _ = crowds.handover().targets

    def bearing(t: Target, at: float) -> float:
        x, y = t.position(at)
        return math.degrees(math.atan2(y, x))

    start = crowds.HANDOVER_START_S
    mid = start + math.dist(crowds.HANDOVER_FROM, crowds.HANDOVER_MID) / crowds.HANDOVER_SPEED_MPS
    assert abs(bearing(alice, start)) < 30 and 60 < bearing(alice, mid) < 120
    assert (bearing(alice, mid) - bearing(alice, start)) / (mid - start) > 30
    assert 60 < bearing(bob, 0.0) < 120
    entering = next(t for t in np.arange(start, mid, 0.05) if bearing(alice, t) >= 60)
    assert abs(bearing(bob, 0.0) - bearing(alice, entering)) <= 20
    assert 60 < bearing(alice, crowds.handover_end_s()) < 120
