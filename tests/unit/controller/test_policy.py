"""The controller's decisions on hand-built detections and scans, with an explicit clock."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from common.boxes import Boxes
from common.contracts import ControllerMode, DistanceSource
from common.errors import ConfigError
from common.messages import Detections, Header, LaserScan
from services.camera.contract import CameraSettings
from services.controller.contract import ControllerSettings
from services.controller.geometry import (
    bearing,
    box_distance,
    corridor_clearance,
    focal_px,
    sector_clearance,
    sector_range,
)
from services.controller.policy import Controller, Inputs
from services.controller.targets import View
from stack.config_file import load_config
from tests.unit.controller.scans import scan_of

HEADER = Header(stamp_ns=123, frame_id="camera", seq=1, source="test")
W, H, HFOV = 640, 480, 60.0
# The highest accelerations the settings allow and a pure P term: a single tick shows the
# policy's intent.
FREE = dict(max_linear_accel=20.0, max_angular_accel=100.0, bearing_kd=0.0)
# Following by box height (the code's default, as deploy/stack.toml's, is the laser).
TRACK = ControllerSettings(
    mode=ControllerMode.TRACK,
    target_classes=("person",),
    distance_source=DistanceSource.BOX,
    **FREE,  # type: ignore[arg-type]
)
FOLLOW = dataclasses.replace(TRACK, mode="follow")
# Today's stack: one camera, looking forward.
FRONT = {"front": CameraSettings(hfov_deg=HFOV)}


def one(
    d: Detections | None,
    age: float,
    sc: LaserScan | None = None,
    scan_age: float = math.inf,
    *,
    estop: bool = False,
    capture_age_s: float = 0.0,
) -> Inputs:
    """The inputs of a one-camera stack: the front camera's detections and their age."""
    return Inputs({"front": View(d, age, capture_age_s)}, sc, scan_age, estop)


def dets(
    *boxes: tuple[str, float, float, float, float, float],
    width: int = W,
    tracks: list[int] | None = None,
) -> Detections:
    """Boxes as (class, score, cx, cy, w, h) in pixels."""
    n = len(boxes)
    xyxy = np.array(
        [[cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2] for _, _, cx, cy, w, h in boxes],
        np.float32,
    ).reshape(n, 4)
    return Detections(
        header=HEADER,
        image_width=width,
        image_height=H,
        boxes=Boxes(
            xyxy=xyxy,
            scores=np.array([b[1] for b in boxes], np.float32),
            class_ids=np.zeros(n, np.int32),
            track_ids=None if tracks is None else np.array(tracks, np.int32),
        ),
        class_names=tuple(b[0] for b in boxes),
    )


def scan(front_range: float, *, rays: int = 181, fov_deg: float = 180.0) -> LaserScan:
    angles = np.linspace(-np.radians(fov_deg / 2), np.radians(fov_deg / 2), rays)
    ranges = np.full(rays, 10.0, np.float32)
    ranges[np.abs(angles) < np.radians(5)] = front_range
    return scan_of(angles, ranges, HEADER)


def step(
    s: ControllerSettings,
    d: Detections | None,
    sc: LaserScan | None = None,
    *,
    age: float = 0.0,
    now: float = 1.0,
    ctl: Controller | None = None,
):  # type: ignore[no-untyped-def]
    ctl = ctl or Controller(s, FRONT)
    return ctl.step(one(d, age, sc, 0.0 if sc is not None else math.inf), now)


# A box tall enough for a 1.7 m person at 2.5 m: beyond the 1.0 m follow distance.
FAR = 1.7 * focal_px(W, HFOV) / 2.5


def test_pinhole_geometry() -> None:
    d = dets(("person", 0.9, W, 240, 50, FAR))  # centre at the right image edge
    assert bearing(d, 0, HFOV) == pytest.approx(-math.radians(HFOV / 2))
    assert box_distance(d, 0, HFOV, 1.7) == pytest.approx(2.5, rel=1e-3)


def test_track_turns_towards_most_central_confident_target() -> None:
    d = dets(
        ("person", 0.9, 600, 240, 50, 100),
        ("person", 0.8, 400, 240, 50, 100),
        ("cup", 0.99, 320, 240, 50, 50),
        ("person", 0.2, 330, 240, 50, 50),
    )
    cmd = step(TRACK, d)
    # the cup is not a target, the 0.2 person is below min_score: the x=400 person is chosen
    assert cmd.target == "person" and cmd.angular_z < 0  # right of centre -> clockwise
    assert cmd.angular_z == pytest.approx(TRACK.bearing_kp * bearing(d, 1, HFOV))
    assert cmd.linear_x == 0.0 and cmd.state == "turning"
    assert cmd.input_stamp_ns == HEADER.stamp_ns


def test_track_drives_forward_only_when_centred() -> None:
    cmd = step(TRACK, dets(("person", 0.9, W / 2 + 10, 240, 50, 100)), scan(5.0))
    assert cmd.linear_x == TRACK.forward_speed and cmd.state == "tracking"
    left = step(TRACK, dets(("person", 0.9, 100, 240, 50, 100)), scan(5.0))
    assert left.angular_z > 0 and left.linear_x == 0.0


@pytest.mark.parametrize("ahead_m", [0.1, 0.2, 0.3, TRACK.safety_distance_m])
def test_track_never_drives_towards_an_obstacle(ahead_m: float) -> None:
    # A centred person beyond the obstacle, and a person off to the left: no forward motion,
    # but turning towards the target is still allowed.
    cmd = step(TRACK, dets(("person", 0.9, W / 2 + 10, 240, 50, 100)), scan(ahead_m))
    assert cmd.linear_x == 0.0 and cmd.state == "blocked" and "obstacle" in cmd.reason
    left = step(TRACK, dets(("person", 0.9, 200, 240, 50, 100)), scan(ahead_m))
    assert left.linear_x == 0.0 and left.angular_z > 0


def test_track_never_drives_without_a_recent_scan() -> None:
    d = dets(("person", 0.9, W / 2 + 10, 240, 50, 100))
    blind = step(TRACK, d)
    assert blind.linear_x == 0.0 and blind.state == "blocked", blind
    assert blind.angular_z != 0.0  # turning in place is still allowed
    ctl = Controller(TRACK, FRONT)
    old = ctl.step(one(d, 0.0, scan(5.0), TRACK.scan_timeout_s + 0.01), now=1.0)
    assert old.linear_x == 0.0 and old.reason == "no recent laser scan", old


def test_no_laser_is_the_only_way_to_drive_without_a_scan() -> None:
    d = dets(("person", 0.9, W / 2 + 10, 240, 50, 100))
    for mode in ("track", "follow"):
        s = dataclasses.replace(TRACK, mode=mode, no_laser=True)
        far = dets(("person", 0.9, 320, 240, 60, FAR)) if mode == "follow" else d
        assert step(s, far).linear_x > 0, mode
        # A scan that does come is still obeyed.
        assert step(s, far, scan(0.2)).state == "blocked", mode
        # A target out of view (held briefly) is not driven on to without a scan.
        ctl = Controller(s, FRONT)
        ctl.step(one(far, 0.0), now=0.0)
        held = ctl.step(one(dets(), 0.0), now=0.1)
        assert held.state == "holding" and held.linear_x == 0.0, mode


def test_no_laser_with_the_laser_for_distance_is_refused() -> None:
    with pytest.raises(ConfigError, match="no_laser"):
        ControllerSettings(mode="follow", distance_source="laser", no_laser=True)  # type: ignore[arg-type]


def test_uses_the_image_width_from_the_message() -> None:
    # x=600 is right of centre in a 640 image but left of centre in a 1280 one
    assert step(TRACK, dets(("person", 0.9, 600, 240, 50, 100), width=1280)).angular_z > 0


def test_angular_speed_is_limited() -> None:
    s = dataclasses.replace(TRACK, bearing_kp=100.0, max_angular=0.7)
    assert step(s, dets(("person", 0.9, 630, 240, 10, 10))).angular_z == pytest.approx(-0.7)


def test_acceleration_is_limited_between_ticks() -> None:
    s = dataclasses.replace(TRACK, max_linear_accel=1.0, max_angular_accel=2.0)
    ctl = Controller(s, FRONT)
    d = dets(("person", 0.9, 330, 240, 50, 100))
    first = ctl.step(one(d, 0.0, scan(5.0), 0.0), now=0.0)  # first tick: one period (1/20 s)
    second = ctl.step(one(d, 0.0, scan(5.0), 0.0), now=0.1)
    assert first.linear_x == pytest.approx(0.05) and second.linear_x == pytest.approx(0.15)


def test_no_target_means_zero() -> None:
    for s, sc in ((TRACK, None), (FOLLOW, scan(5.0))):
        cmd = step(s, dets(("cup", 0.9, 320, 240, 50, 50)), sc)
        assert cmd.is_zero and cmd.state == "searching"


def test_follow_keeps_the_distance() -> None:
    far = step(FOLLOW, dets(("person", 0.9, 320, 240, 60, FAR)), scan(5.0))
    assert far.state == "following"
    assert far.linear_x == pytest.approx(min(FOLLOW.max_linear, FOLLOW.distance_gain * 1.5))
    near = step(
        FOLLOW, dets(("person", 0.9, 320, 240, 200, 1.7 * focal_px(W, HFOV) / 0.9)), scan(5.0)
    )
    assert near.linear_x == 0.0 and near.state == "arrived"


def test_follow_by_laser_measures_in_the_target_bearing() -> None:
    s = dataclasses.replace(FOLLOW, distance_source="laser")
    d = dets(("person", 0.9, 320, 240, 60, 20))  # a tiny box: "far" by its height
    assert step(s, d, scan(0.9)).state == "arrived"  # but the laser says 0.9 m
    assert step(s, d, scan(3.0)).state == "following"
    assert step(s, d, None).state == "blocked"


def test_follow_stops_for_an_obstacle_ahead() -> None:
    d = dets(("person", 0.9, 320, 240, 60, FAR))
    assert step(FOLLOW, d, scan(0.3)).state == "blocked"
    assert step(FOLLOW, d, scan(0.3)).linear_x == 0.0
    assert step(FOLLOW, d, None).state == "blocked"  # no scan: cannot tell it is clear
    assert step(FOLLOW, d, scan(0.8)).linear_x > 0


def test_follow_locks_onto_one_track() -> None:
    ctl = Controller(FOLLOW, FRONT)
    big_a = ("person", 0.9, 250.0, 240.0, 80.0, FAR)
    bigger_b = ("person", 0.9, 420.0, 240.0, 120.0, FAR * 1.1)
    first = ctl.step(one(dets(big_a, tracks=[7]), 0.0, scan(5.0), 0.0), now=0.0)
    assert first.track_id == 7
    # another, larger person appears: the lock holds on track 7
    second = ctl.step(one(dets(big_a, bigger_b, tracks=[7, 8]), 0.0, scan(5.0), 0.0), 0.1)
    assert second.track_id == 7 and second.angular_z > 0


def test_lost_target_is_held_briefly_then_dropped() -> None:
    ctl = Controller(FOLLOW, FRONT)
    seen = dets(("person", 0.9, 320, 240, 60, FAR), tracks=[3])
    empty = dets()
    ctl.step(one(seen, 0.0, scan(5.0), 0.0), now=0.0)
    held = ctl.step(one(empty, 0.0, scan(5.0), 0.0), now=FOLLOW.target_lost_timeout_s / 2)
    assert held.state == "holding" and held.linear_x > 0
    lost = ctl.step(one(empty, 0.0, scan(5.0), 0.0), now=FOLLOW.target_lost_timeout_s + 0.1)
    assert lost.is_zero and lost.state == "searching"
    # unlocked: after the relock window a new person is followed (a switch, counted)
    other = dets(("person", 0.9, 320, 240, 60, FAR), tracks=[9])
    later = FOLLOW.target_lost_timeout_s + 0.2 + FOLLOW.relock_window_s
    assert ctl.step(one(other, 0.0, scan(5.0), 0.0), now=later).track_id == 9
    assert (ctl.locks_switched, ctl.locks_regained) == (1, 0)


def test_a_lost_target_is_waited_for_and_nobody_else_is_locked_meanwhile() -> None:
    """alice (track 3) is hidden past the lost timeout while bob (track 9) stands in view: the
    robot searches, standing still, instead of following bob; alice's track shows again
    (the Kalman tracker gives her back her id) and the lock is hers again."""
    ctl = Controller(FOLLOW, FRONT)
    alice = ("person", 0.9, 320, 240, 80, FAR * 1.2)
    bob = ("person", 0.9, 500, 240, 60, FAR)
    first = ctl.step(one(dets(alice, bob, tracks=[3, 9]), 0.0, scan(5.0), 0.0), now=0.0)
    assert first.track_id == 3  # the larger
    t = FOLLOW.target_lost_timeout_s + 0.1
    only_bob = dets(bob, tracks=[9])
    assert ctl.step(one(only_bob, 0.0, scan(5.0), 0.0), now=t).state == "searching"
    waiting = ctl.step(one(only_bob, 0.0, scan(5.0), 0.0), now=t + 1.0)
    assert waiting.is_zero and waiting.state == "searching" and waiting.track_id != 9
    back = ctl.step(one(dets(alice, bob, tracks=[3, 9]), 0.0, scan(5.0), 0.0), now=t + 1.5)
    assert back.track_id == 3 and back.state != "searching"
    assert (ctl.locks_regained, ctl.locks_switched) == (1, 0)


def test_held_target_does_not_drive_into_an_obstacle() -> None:
    ctl = Controller(FOLLOW, FRONT)
    ctl.step(one(dets(("person", 0.9, 320, 240, 60, FAR)), 0.0, scan(5.0), 0.0), now=0.0)
    held = ctl.step(one(dets(), 0.0, scan(0.2), 0.0), now=0.1)
    assert held.state == "holding" and held.linear_x == 0.0


def test_sector_checks_a_sector_not_one_ray() -> None:
    s = scan(10.0)
    ranges = s.ranges.copy()
    ranges[np.argmin(np.abs(s.angles - np.radians(10)))] = 0.2  # 10 deg off-axis
    off_axis = dataclasses.replace(s, ranges=ranges)
    assert sector_clearance(off_axis, 30.0) == pytest.approx(0.2)
    assert sector_clearance(off_axis, 10.0) == pytest.approx(10.0)
    assert sector_range(off_axis, np.radians(10), 4.0) == pytest.approx(0.2)


def test_sector_ignores_invalid_rays_and_blind_is_blocked() -> None:
    assert sector_clearance(scan(np.nan), 8.0) == 0.0  # every ray in the sector is NaN
    assert sector_clearance(scan(0.01), 8.0) == 0.0  # below range_min: invalid -> blind


def test_stale_or_missing_detections_and_estop_command_zero_at_once() -> None:
    ctl = Controller(dataclasses.replace(TRACK, max_linear_accel=0.1), FRONT)
    d = dets(("person", 0.9, 320, 240, 50, 100))
    for t in range(20):
        moving = ctl.step(one(d, 0.0, scan(5.0), 0.0), now=t * 0.1)
    assert moving.linear_x > 0
    stale = ctl.step(one(d, TRACK.detection_timeout_s + 0.01), now=2.1)
    assert stale.is_zero and stale.state == "stale"  # no deceleration ramp for a stop
    assert ctl.step(one(None, math.inf), now=2.2).state == "stale"
    estop = ctl.step(one(d, 0.0, estop=True), now=2.3)
    assert estop.is_zero and estop.state == "estop"


def test_obstacle_stop_leaves_room_to_brake() -> None:
    s = dataclasses.replace(FOLLOW, max_linear_accel=0.5)
    ctl = Controller(s, FRONT)
    d = dets(("person", 0.9, 320, 240, 60, FAR))
    for t in range(40):  # reach cruising speed with a clear way
        ctl.step(one(d, 0.0, scan(8.0), 0.0), now=t * 0.05)
    v = ctl.previous[0]
    assert v > 0.4
    # 0.6 m ahead is beyond the 0.5 m safety distance but within it plus the braking distance
    cmd = ctl.step(one(d, 0.0, scan(0.5 + v * v / (2 * 0.5)), 0.0), now=2.0)
    assert cmd.state == "blocked"


def test_corridor_catches_what_the_sector_misses() -> None:
    # A box 0.6 m ahead and 0.25 m to the side: 22 degrees off-axis, outside a 30 degree sector,
    # but inside the corridor of a 0.6 m wide robot.
    angles = np.linspace(-np.pi / 2, np.pi / 2, 361)
    ranges = np.full(angles.size, np.inf, np.float32)
    ranges[np.argmin(np.abs(angles - math.atan2(0.25, 0.6)))] = math.hypot(0.6, 0.25)
    s = scan_of(angles, ranges, HEADER)
    assert sector_clearance(s, 30.0) == math.inf
    assert sector_clearance(s, 30.0, half_width_m=0.3) == pytest.approx(0.6, abs=0.01)
    assert corridor_clearance(s, 0.2) == math.inf


def test_rotation_since_integrates_the_commanded_turns() -> None:
    ctl = Controller(TRACK, FRONT)
    ctl.turns.extend([(0.0, 0.3, 0.5), (1.0, 0.1, -0.2), (2.0, 0.0, 0.0)])
    assert ctl.rotation_since(0.0, 3.0) == pytest.approx(0.5 - 0.2)
    assert ctl.rotation_since(0.5, 1.5) == pytest.approx(0.25 - 0.1)
    assert ctl.travel_since(0.0, 3.0) == pytest.approx(0.3 + 0.1)
    assert ctl.travel_since(0.5, 1.5) == pytest.approx(0.15 + 0.05)


def test_bearing_is_compensated_for_the_turn_since_capture() -> None:
    ctl = Controller(TRACK, FRONT)
    ctl.turns.append((0.0, 0.0, 0.5))  # turning left at 0.5 rad/s for the last second
    d = dets(("person", 0.9, 200, 240, 50, 100))  # seen left of centre a second ago
    measured = bearing(d, 0, HFOV)
    assert measured > 0
    cmd = ctl.step(one(d, 0.0, capture_age_s=1.0), now=1.0)
    # The robot already turned 0.5 rad left: the target is now to the right.
    assert cmd.angular_z == pytest.approx(TRACK.bearing_kp * (measured - 0.5), abs=1e-6)


def test_a_distance_measured_on_the_frame_is_net_of_the_drive_since_its_capture() -> None:
    """The box says 2.5 m on a frame captured a second ago; the robot drove 0.4 m since. The
    command's distance is 2.1 m: without the drive a slow detector's follower ends nearer than
    follow_distance_m by its speed times the latency."""
    seen = dets(("person", 0.9, 320, 240, 60, FAR))
    fresh = Controller(FOLLOW, FRONT).step(one(seen, 0.0, scan(8.0), 0.0), now=1.0)
    assert "target at 2.50 m" in fresh.reason
    ctl = Controller(FOLLOW, FRONT)
    ctl.turns.append((0.0, 0.4, 0.0))  # driving at 0.4 m/s for the last second
    late = ctl.step(one(seen, 0.0, scan(8.0), 0.0, capture_age_s=1.0), now=1.0)
    assert "target at 2.10 m" in late.reason
    ctl = Controller(FOLLOW, FRONT)
    ctl.turns.append((0.0, 1.6, 0.0))  # it drove 1.6 m: 0.9 m left, within follow_distance_m
    assert ctl.step(one(seen, 0.0, scan(8.0), 0.0, capture_age_s=1.0), now=1.0).state == "arrived"


def test_losing_the_target_stops_at_once_after_the_hold() -> None:
    s = dataclasses.replace(FOLLOW, max_linear_accel=0.5)
    ctl = Controller(s, FRONT)
    seen = dets(("person", 0.9, 320, 240, 60, FAR))
    for t in range(60):
        ctl.step(one(seen, 0.0, scan(8.0), 0.0), now=t * 0.05)
    assert ctl.previous[0] > 0.4
    lost = ctl.step(one(dets(), 0.0, scan(8.0), 0.0), now=3.0 + s.target_lost_timeout_s + 0.1)
    assert lost.is_zero and lost.state == "searching"  # no braking ramp


def test_track_mode_does_not_hold_forward_speed_blind() -> None:
    ctl = Controller(TRACK, FRONT)
    ctl.step(one(dets(("person", 0.9, 320, 240, 50, 100)), 0.0), now=0.0)
    held = ctl.step(one(dets(), 0.0), now=0.1)  # no scan in track mode
    assert held.state == "holding" and held.linear_x == 0.0


def test_corridor_with_rays_at_infinity_raises_no_numpy_warning() -> None:
    import warnings

    ranges = np.full(541, np.inf, np.float32)
    ranges[270] = 2.0  # straight ahead
    scan = LaserScan(
        header=Header(stamp_ns=1, frame_id="laser", seq=0, source="sim"),
        angle_min=-2.356, angle_increment=4.712 / 540, range_min=0.05, range_max=12.0,
        ranges=ranges,
    )  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "invalid value encountered in multiply" fails here
        assert corridor_clearance(scan, 0.3) == pytest.approx(2.0)


def test_the_code_and_the_default_stack_file_drive_in_one_mode() -> None:
    stack_file = Path(__file__).resolve().parents[3] / "deploy" / "stack.toml"
    assert load_config(stack_file, environ={}).controller.mode == ControllerSettings().mode


def test_after_a_stalled_tick_the_room_to_brake_is_for_the_speed_it_may_now_command() -> None:
    # At rest, 0.55 m from an obstacle (beyond the 0.5 m safety distance). The next tick comes
    # 0.6 s late (a loaded machine): the acceleration limit would allow 0.3 m/s at once, and
    # 0.3 m/s needs more room than 0.05 m. Judged by the speed before the stall (0), it drove.
    s = dataclasses.replace(TRACK, max_linear_accel=1.0)
    ctl = Controller(s, FRONT)
    d = dets(("person", 0.9, W / 2 + 10, 240, 50, 100))
    assert ctl.step(one(d, 0.0, scan(0.55), 0.0), now=0.0).state == "tracking"  # 0.05 m/s
    ctl.previous = (0.0, 0.0)  # at rest
    late = ctl.step(one(d, 0.0, scan(0.55), 0.0), now=0.6)
    assert late.linear_x == 0.0 and late.state == "blocked", late


def test_a_target_striding_out_of_view_is_turned_after_not_looked_for_where_it_was() -> None:
    """alice crosses the view leftwards, then is lost: holding, the robot turns towards where
    she should be by now (her bearing's rate, the robot's own turn taken out), further left
    than where she was last seen; with hold_bearing_rate 0 it turns to where she was."""

    def holding_turn(rate_max: float) -> float:
        s = dataclasses.replace(FOLLOW, hold_bearing_rate=rate_max)
        ctl = Controller(s, FRONT)
        for k in range(5):
            seen = dets(("person", 0.9, 320 - 50 * k, 240, 60, FAR), tracks=[4])
            ctl.step(one(seen, 0.0, scan(5.0), 0.0), now=0.2 * k)
        held = ctl.step(one(dets(), 0.0, scan(5.0), 0.0), now=1.2)
        assert held.state == "holding"
        return held.angular_z

    assert holding_turn(1.0) > holding_turn(0.0) > 0
