"""The simulator's pure parts: kinematics, the laser, the camera's geometry, the scoring."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from common.messages import GroundTruth, Header, Twist
from services.controller.contract import ControllerSettings
from simworld.body import Body
from simworld.laser import LaserSpec, cast
from simworld.people import HIPS_HALF_SHARE, surface_m
from simworld.render import CameraSpec, render
from simworld.scenarios import SCENARIOS, card
from simworld.world import BaseLimits, Obstacle, Robot, Target, World, flat_world
from tools.scenarios.score import ScenarioLog, score, stale_commands

FREE = BaseLimits(max_linear=9, max_angular=9, max_linear_accel=1e9, max_angular_accel=1e9)


def test_straight_line_and_arc() -> None:
    r = Robot()
    for _ in range(100):
        r.step((0.5, 0.0), 0.01, FREE)
    assert (r.x, r.y) == pytest.approx((0.5, 0.0))
    r = Robot()
    for _ in range(1000):  # v = 1, w = pi/2 for 1 s: a quarter circle of radius 2/pi
        r.step((1.0, math.pi / 2), 0.001, FREE)
    radius = 2 / math.pi
    assert (r.x, r.y, r.theta) == pytest.approx((radius, radius, math.pi / 2), abs=1e-6)


def test_base_limits_and_watchdog() -> None:
    w = World(Robot(), limits=BaseLimits(max_linear=0.6, max_linear_accel=1.0, watchdog_s=0.5))
    assert w.command(1.0, 0.0)  # over the limit, not absurdly: clamped
    w.advance(0.1)
    assert w.robot.v == pytest.approx(0.1)  # acceleration limit
    for _ in range(20):
        w.advance(0.1)
    assert w.robot.v == pytest.approx(0.0)  # no command for 0.5 s: the base stopped itself


def test_an_absurd_command_is_refused_and_the_base_stops() -> None:
    w = World(Robot(), limits=BaseLimits(max_linear=0.6, max_angular=1.5, max_linear_accel=10.0))
    assert w.command(0.5, 0.0)
    w.advance(0.1)
    assert w.robot.v == pytest.approx(0.5)
    for v, turn in ((1e308, 0.0), (-50.0, 0.0), (0.0, 4.0)):
        assert not w.command(v, turn)
        w.advance(0.1)
        assert w.robot.v == pytest.approx(0.0) and w.robot.w == pytest.approx(0.0)


def test_laser_hits_the_nearest_surface() -> None:
    spec = LaserSpec(fov_deg=180.0, rays=181, noise_std_m=0.0)
    circles = np.array([[2.0, 0.0, 0.5], [5.0, 0.0, 0.5]])
    ranges = cast((0.0, 0.0, 0.0), circles, spec)
    assert ranges[90] == pytest.approx(1.5)  # straight ahead: the near circle's surface
    assert np.isinf(ranges[0]) and np.isinf(ranges[-1])  # to the sides: nothing
    turned = cast((0.0, 0.0, math.pi / 2), circles, spec)
    assert turned[0] == pytest.approx(1.5)  # facing +y, the circle is on the right ray


def test_person_is_rendered_where_the_pinhole_model_says() -> None:
    spec = CameraSpec(width=640, height=480, hfov_deg=60.0, height_m=0.6)
    world = World(Robot(), targets=[card("a", (0, 3.0, 0.0))])
    img = render(world, spec)
    empty = render(World(Robot()), spec)
    changed = np.any(img != empty, axis=2)
    ys, xs = np.nonzero(changed)
    f = spec.focal_px
    sprite_h = f * 1.7 / 3.0
    assert xs.mean() == pytest.approx(320, abs=5)
    assert ys.max() == pytest.approx(240 + f * 0.6 / 3.0, abs=2)  # feet on the floor
    assert ys.max() - ys.min() == pytest.approx(min(sprite_h, ys.max()), abs=3)


def test_every_scenario_builds() -> None:
    for sc in SCENARIOS.values():
        world = sc.build()
        assert sc.followed is None or sc.followed in [t.id for t in world.targets]


HDR = Header(stamp_ns=0, frame_id="", seq=0, source="t")


def _twist(t_ns: int, v: float, input_ns: int = 0) -> Twist:
    header = Header(stamp_ns=t_ns, frame_id="", seq=0, source="c")
    return Twist(header=header, linear=(v, 0, 0), input_stamp_ns=input_ns)


def test_stale_commands_counts_moving_commands_on_frames_older_than_the_timeout() -> None:
    s = 1_000_000_000
    rec = ScenarioLog(
        twists=[
            _twist(int(1.5 * s), 0.3, input_ns=1 * s),  # 0.5 s old: fresh
            _twist(3 * s, 0.0, input_ns=1 * s),  # zero: fine however old
            _twist(3 * s, 0.3, input_ns=1 * s),  # moving on a 2 s old frame: stale
            _twist(2 * s, 0.3, input_ns=1 * s),  # exactly the timeout: still fresh
            _twist(int(0.5 * s), 0.3),  # moving on no input at all: stale
        ],
    )
    assert stale_commands(rec, timeout_s=1.0) == 2


def test_score_reach_and_verdict() -> None:
    sc = SCENARIOS["ahead"]
    s = ControllerSettings(mode="follow")
    truths = [
        GroundTruth(
            header=HDR,
            sim_time_s=t,
            robot=(x, 0.0, 0.0),
            targets_xy=np.array([[4.0, 0.0]]),
            target_names=("person",),
            target_ids=("alice",),
        )
        for t, x in ((0.5, 0.0), (5.0, 2.0), (9.0, 2.8))
    ]
    # The flat card's surface is its radius; a body's its torso on the line to the robot
    # (alice stands facing the robot: half her depth).
    flat = score(sc, ScenarioLog(truths=truths), flat_world(sc.build()), s, 60.0)
    assert flat["final_distance_m"] == pytest.approx(4.0 - 2.8 - 0.25)
    result = score(sc, ScenarioLog(truths=truths), sc.build(), s, 60.0)
    body = sc.build().targets[0].body
    assert body is not None
    assert result["final_distance_m"] == pytest.approx(4.0 - 2.8 - body.depth_m / 2)
    assert result["time_to_reach_s"] == 9.0
    assert result["success"] and result["checks"]["reached the stop distance"]
    far = score(sc, ScenarioLog(truths=truths[:2]), sc.build(), s, 60.0)
    assert not far["success"]


def test_min_clearance_is_to_the_obstacle_surface() -> None:
    sc = SCENARIOS["obstacle"]
    truths = [
        GroundTruth(
            header=HDR,
            sim_time_s=1.0,
            robot=(1.7, 0.0, 0.0),
            targets_xy=np.array([[5.5, 0.3]]),
            target_names=("person",),
            target_ids=("alice",),
        )
    ]
    world = World(Robot(), obstacles=[Obstacle(2.5, 0.0, 0.3)], targets=sc.build().targets)
    result = score(sc, ScenarioLog(truths=truths), world, ControllerSettings(), 60.0)
    assert result["min_clearance_m"] == pytest.approx(0.5)


def test_demo_person_stays_in_view_of_a_follower_for_ten_minutes() -> None:
    """The demo walk, followed by an idealised follower (bearing P control, distance gain,
    forward only when centred, 0.4 s perception latency, the base's limits): the person never
    leaves a 60 degree field of view and never comes within reach of being passed."""
    import math

    from simworld.scenarios import SCENARIOS

    world = SCENARIOS["demo"].build()
    dt, latency_steps = 0.05, 8
    seen: list[tuple[float, float]] = []
    worst_bearing, nearest = 0.0, math.inf
    for _ in range(int(600 / dt)):
        r = world.robot
        tx, ty = world.target_positions()[0]
        bearing = math.atan2(ty - r.y, tx - r.x) - r.theta
        bearing = math.atan2(math.sin(bearing), math.cos(bearing))
        distance = math.hypot(tx - r.x, ty - r.y)
        seen.append((bearing, distance))
        if world.t > 5.0:  # after the first approach
            worst_bearing = max(worst_bearing, abs(math.degrees(bearing)))
            nearest = min(nearest, distance)
        b, d = seen[max(0, len(seen) - 1 - latency_steps)]
        w = max(-1.0, min(1.0, 1.5 * b))
        v = max(0.0, min(0.5, 0.6 * (d - 1.25))) if abs(math.degrees(b)) < 15 else 0.0
        world.command(v, w)
        world.advance(dt)
    assert worst_bearing < 30.0, worst_bearing
    assert nearest > 0.7, nearest


def test_in_appears_bob_is_in_no_cameras_view_but_the_rears_while_he_steps_in() -> None:
    """Scenario "appears" (the attention benchmark): bob's bearing from each of its cameras,
    the robot anywhere on its way to alice (x from 0 to 3 m, facing her)."""
    from simworld.scenarios import APPEARS_AT_S, APPEARS_STAY_S, APPEARS_STEP_S

    sc = SCENARIOS["appears"]
    bob = next(t for t in sc.build().targets if t.id == "bob")
    yaws = {"front": 0.0, **{c: v["mount_yaw_deg"] for c, v in sc.cameras.items()}}
    half_fov = 30.0 + 5.0  # the default 60 degrees, and a margin for bob's width

    def seen_by(t: float, robot_x: float) -> set[str]:
        bx, by = bob.position(t)
        b = math.degrees(math.atan2(by, bx - robot_x))
        off = {c: (b - yaw + 180.0) % 360.0 - 180.0 for c, yaw in yaws.items()}
        return {c for c, d in off.items() if abs(d) <= half_fov}

    for x in (0.0, 1.5, 3.0):
        assert seen_by(0.0, x) == set()
        for t in APPEARS_AT_S:
            assert seen_by(t, x) == set()  # out of every view until he steps in
            assert seen_by(t + APPEARS_STEP_S, x) == {"rear"}
            assert seen_by(t + APPEARS_STEP_S + APPEARS_STAY_S, x) == {"rear"}
            assert seen_by(t + 2 * APPEARS_STEP_S + APPEARS_STAY_S, x) == set()
    assert sc.duration_s > APPEARS_AT_S[-1] + APPEARS_STEP_S + APPEARS_STAY_S


def test_a_body_s_surface_is_half_its_depth_front_on_and_half_its_hips_side_on() -> None:
    body = Body(shoulder_m=0.5, depth_m=0.3, facing_deg=180.0)  # faces -x: the robot at origin
    tg = Target("p", "person", "person", 1.75, path=((0.0, 3.0, 0.0),), body=body)
    assert surface_m(tg, 0.0, (0.0, 0.0)) == pytest.approx(0.15)
    assert surface_m(tg, 0.0, (3.0, -2.0)) == pytest.approx(HIPS_HALF_SHARE * 0.5)  # side-on
    between = surface_m(tg, 0.0, (1.0, -2.0))
    assert 0.15 < between < HIPS_HALF_SHARE * 0.5
    assert surface_m(dataclasses.replace(tg, body=None), 0.0, (0.0, 0.0)) == tg.radius
