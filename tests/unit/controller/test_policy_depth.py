"""The controller's decisions with depth (issue 32): the way ahead checked by the depth cameras'
virtual scan (``obstacle_sources``) and the target's distance from its ``distance_m`` column
(``distance_source = "depth"``); the settings that cannot go together refused."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from common.boxes import Boxes
from common.errors import ConfigError
from common.messages import Detections, LaserScan
from services.controller.contract import ControllerSettings
from services.controller.policy import Controller, Inputs, VelocityCommand
from services.controller.targets import View
from tests.unit.controller.test_policy import FREE, FRONT, HEADER, H, W, scan

TRACK = ControllerSettings(mode="track", obstacle_sources=("depth",), **FREE)  # type: ignore[arg-type]
FOLLOW = dataclasses.replace(TRACK, mode="follow", distance_source="depth")  # type: ignore[arg-type]


def person(
    distance_m: float | None = None, cx: float = W / 2, *, above_m: float = 0.0
) -> Detections:
    """One centred person (100x200 px); with ``distance_m``, its depth columns: its centre
    ``distance_m`` straight ahead of the camera across the floor and ``above_m`` above it
    (``distance_m`` the 3D norm)."""
    columns = {}
    if distance_m is not None:
        norm = math.hypot(distance_m, above_m)
        for name, value in (("distance_m", norm), ("x_m", 0.0), ("y_m", -above_m)):
            columns[name] = np.array([value], np.float32)
        columns["z_m"] = np.array([distance_m], np.float32)
    return Detections(
        header=HEADER, image_width=W, image_height=H, class_names=("person",),
        boxes=Boxes(
            xyxy=np.array([[cx - 50, 140, cx + 50, 340]], np.float32),
            scores=np.array([0.9], np.float32), class_ids=np.zeros(1, np.int32),
            columns=columns,
        ),
    )  # fmt: skip


def step(
    s: ControllerSettings,
    d: Detections,
    *,
    depth: LaserScan | None = None,
    depth_age_s: float = 0.0,
    laser: LaserScan | None = None,
    missing: str = "no depth from front yet",
) -> VelocityCommand:
    inputs = Inputs(
        {"front": View(d, 0.0, 0.0)},
        laser,
        0.0 if laser is not None else math.inf,
        False,
        depth,
        depth_age_s if depth is not None else math.inf,
        missing if depth is None else "",
    )
    return Controller(s, FRONT).step(inputs, 1.0)


def test_depth_that_shows_the_way_clear_allows_forward_motion() -> None:
    cmd = step(TRACK, person(), depth=scan(5.0))
    assert cmd.state == "tracking" and cmd.linear_x > 0, cmd
    # With no laser at all: the laser is not what this robot needs.
    assert "laser" not in cmd.reason


def test_no_depth_or_stale_depth_means_no_forward_motion() -> None:
    blind = step(TRACK, person(), missing="no depth from front yet")
    assert blind.state == "blocked" and blind.linear_x == 0.0
    assert blind.reason == "no depth from front yet"
    stale = step(TRACK, person(), depth=scan(5.0), depth_age_s=TRACK.depth_timeout_s + 0.01)
    assert stale.state == "blocked" and stale.linear_x == 0.0, stale
    # A laser scan showing the way clear does not stand in for the depth the settings need.
    covered = step(TRACK, person(), laser=scan(5.0))
    assert covered.state == "blocked" and covered.linear_x == 0.0


@pytest.mark.parametrize("ahead_m", [0.2, TRACK.safety_distance_m])
def test_an_obstacle_in_the_depth_stops_forward_motion(ahead_m: float) -> None:
    cmd = step(TRACK, person(), depth=scan(ahead_m))
    assert cmd.state == "blocked" and cmd.linear_x == 0.0
    assert cmd.reason == f"obstacle at {ahead_m:.2f} m (depth)"


def test_every_fresh_source_is_obeyed_listed_or_not() -> None:
    # Depth listed and clear, a laser scan not listed but fresh shows an obstacle: stop.
    cmd = step(TRACK, person(), depth=scan(5.0), laser=scan(0.3))
    assert cmd.state == "blocked" and cmd.reason == "obstacle at 0.30 m", cmd
    # The laser listed (the default) and clear, fresh depth shows an obstacle: stop.
    laser_robot = dataclasses.replace(TRACK, obstacle_sources=("laser",))
    cmd = step(laser_robot, person(), depth=scan(0.3), laser=scan(5.0))
    assert cmd.state == "blocked" and cmd.reason == "obstacle at 0.30 m (depth)", cmd
    # Both listed: each must be fresh.
    both = dataclasses.replace(TRACK, obstacle_sources=("laser", "depth"))
    assert step(both, person(), laser=scan(5.0)).reason == "no depth from front yet"
    assert step(both, person(), depth=scan(5.0)).reason == "no recent laser scan"
    assert step(both, person(), laser=scan(5.0), depth=scan(5.0)).state == "tracking"


def test_follow_keeps_the_distance_the_depth_column_gives() -> None:
    far = step(FOLLOW, person(3.0), depth=scan(8.0))
    assert far.state == "following" and far.reason == "target at 3.00 m", far
    assert far.linear_x == pytest.approx(min(FOLLOW.max_linear, FOLLOW.distance_gain * 2.0))
    near = step(FOLLOW, person(FOLLOW.follow_distance_m - 0.1), depth=scan(8.0))
    assert near.state == "arrived" and near.linear_x == 0.0


@pytest.mark.parametrize("distance", [None, math.nan, 0.0], ids=["absent", "nan", "zero"])
def test_follow_with_the_target_depth_unknown_turns_only(distance: float | None) -> None:
    cmd = step(FOLLOW, person(distance), depth=scan(8.0))
    assert cmd.state == "blocked" and cmd.linear_x == 0.0, cmd
    assert cmd.reason == "the target's depth is unknown"
    off = step(FOLLOW, person(distance, cx=100), depth=scan(8.0))
    assert off.state == "turning" and off.linear_x == 0.0 and off.angular_z > 0


def test_a_target_out_of_view_is_driven_on_to_only_with_the_way_known_clear() -> None:
    ctl = Controller(TRACK, FRONT)
    seen = Inputs({"front": View(person(), 0.0, 0.0)}, depth=scan(5.0), depth_age_s=0.0)
    assert ctl.step(seen, 1.0).state == "tracking"
    gone = Detections(
        header=HEADER, image_width=W, image_height=H, class_names=(),
        boxes=Boxes(xyxy=np.zeros((0, 4), np.float32), scores=np.zeros(0, np.float32),
                    class_ids=np.zeros(0, np.int32)),
    )  # fmt: skip
    held = ctl.step(Inputs({"front": View(gone, 0.0, 0.0)}, depth=scan(5.0), depth_age_s=0.0), 1.05)
    assert held.state == "holding" and held.linear_x > 0, held
    blind = ctl.step(Inputs({"front": View(gone, 0.0, 0.0)}), 1.1)
    assert blind.state == "holding" and blind.linear_x == 0.0, blind


@pytest.mark.parametrize(
    "settings, says",
    [
        (
            {"no_laser": True, "distance_source": "box", "obstacle_sources": ("depth",)},
            "contradicts",
        ),
        (
            {"no_laser": True, "distance_source": "box", "obstacle_sources": ("laser", "depth")},
            "contradicts",
        ),
        ({"no_laser": True, "distance_source": "depth"}, 'distance_source = "depth"'),
        ({"obstacle_sources": ("sonar",)}, "must name each of"),
        ({"obstacle_sources": ("depth", "depth")}, "must name each of"),
        ({"obstacle_sources": ()}, "1..2 items"),
        ({"depth_max_height_m": 0.05, "depth_floor_margin_m": 0.1}, "must be above"),
    ],
)
def test_settings_at_odds_are_refused_in_one_line(settings: dict[str, object], says: str) -> None:
    with pytest.raises(ConfigError, match=says) as err:
        ControllerSettings(**settings)  # type: ignore[arg-type]
    assert "\n" not in str(err.value)


def test_depth_is_read_only_when_needed() -> None:
    assert not ControllerSettings().needs_depth
    assert ControllerSettings(obstacle_sources=("depth",)).needs_depth
    assert ControllerSettings(distance_source="depth").needs_depth  # type: ignore[arg-type]
    # A laser robot that measures the target by depth: the laser checks the way.
    laser_robot = ControllerSettings(distance_source="depth")  # type: ignore[arg-type]
    assert laser_robot.laser_required
    assert not ControllerSettings(obstacle_sources=("depth",)).laser_required


@dataclasses.dataclass(frozen=True)
class Mounted:
    """A camera's announced geometry (CameraAnnouncement's mount fields)."""

    hfov_deg: float = 60.0
    mount_yaw_deg: float = 0.0
    mount_x_m: float = 0.0
    mount_y_m: float = 0.0
    mount_height_m: float = 0.0


def test_follow_compares_the_horizontal_distance_from_the_base() -> None:
    # The target's centre 0.95 m ahead across the floor and 0.4 m above the camera: 1.03 m
    # away in 3D. Followed at 1 m, it is near enough: the 3D distance would drive on.
    high = step(FOLLOW, person(0.95, above_m=0.4), depth=scan(8.0))
    assert high.state == "arrived" and high.linear_x == 0.0, high
    # A camera 0.3 m ahead of the base's centre: the target 0.9 m from it is 1.2 m from the
    # base, and 0.2 m left of it too: the distance is from the base.
    ctl = Controller(FOLLOW, {"front": Mounted(mount_x_m=0.3, mount_y_m=0.2)})  # type: ignore[dict-item]
    inputs = Inputs(
        {"front": View(person(0.9), 0.0, 0.0)}, depth=scan(8.0), depth_age_s=0.0, depth_missing=""
    )
    cmd = ctl.step(inputs, 1.0)
    assert cmd.state == "following" and cmd.reason == "target at 1.22 m", cmd


@pytest.mark.parametrize("s", [TRACK, FOLLOW], ids=["track", "follow"])
def test_the_robot_creeps_while_the_floor_ahead_is_unseen(s: ControllerSettings) -> None:
    # Issue 38: at start-up the depth camera's blind zone (to 1.39 m) has never been seen.
    inputs = Inputs(
        {"front": View(person(5.0), 0.0, 0.0)}, None, math.inf, False, scan(5.0), 0.0, "",
        depth_known_m=0.3,
    )  # fmt: skip
    cmd = Controller(s, FRONT).step(inputs, 1.0)
    assert 0 < cmd.linear_x <= s.depth_creep_speed, cmd
    assert "creeping: the floor is known only 0.30 m ahead (depth)" in cmd.reason
    known = Controller(s, FRONT).step(dataclasses.replace(inputs, depth_known_m=3.0), 1.0)
    assert known.linear_x > s.depth_creep_speed and "creeping" not in known.reason


def test_a_sector_with_no_reading_is_said_so_not_an_obstacle_at_zero() -> None:
    # Issue 39: "blocked: obstacle at 0.00 m (depth)" with nothing within 0.8 m. A virtual
    # scan whose rays straight ahead hold no reading (out of view, or every pixel a hole)
    # blocks, and its status says what is really happening.
    blind = scan(5.0)
    ahead = np.abs(blind.angles) <= math.radians(TRACK.sector_width_deg) / 2
    ranges = blind.ranges.copy()
    ranges[ahead] = np.nan
    blind = dataclasses.replace(blind, ranges=ranges)
    cmd = step(TRACK, person(), depth=blind)
    assert cmd.state == "blocked" and cmd.linear_x == 0.0, cmd
    assert cmd.reason == "nothing seen straight ahead (depth)", cmd.reason
