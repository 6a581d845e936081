"""The virtual scan made from a depth image (depthscan/; services/controller/depth_obstacles.py),
images of known scenes (tests.unit.depthscan.depth_scenes.py): the floor taken out by the
camera's height, obstacles at the right range and angle in the robot's frame, the mounting's
yaw and position applied, what no camera sees unknown."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from common.messages import Header, LaserScan
from depthscan.frame import MIN_NEAR_M, ScanParams, usable
from depthscan.observe import virtual_scan
from perception.depth import DISTANCE, Mounting
from services.controller.depth_obstacles import DepthCamera, depth_obstacles, looks_ahead, merge
from services.controller.geometry import DISTANCE_COLUMN, sector_clearance
from tests.unit.depthscan.depth_scenes import HFOV, INTR, Face, at_bearing, scene

HEADER = Header(stamp_ns=1_000, frame_id="camera", seq=1, source="test")
PARAMS = ScanParams()  # floor margin 0.05 m, max height 1.5 m, every 4th pixel, 1 deg rays
HEIGHT = 0.6
LEVEL = Mounting(height_m=HEIGHT)  # at the base's centre, looking forward


def scan(depth: np.ndarray, mount: Mounting = LEVEL) -> LaserScan:
    return virtual_scan(depth, INTR, mount, PARAMS, HEADER, 10.0)


def ray(s: LaserScan, bearing_deg: float) -> float:
    """The range of the ray nearest ``bearing_deg`` (robot frame)."""
    off = np.abs(np.angle(np.exp(1j * (s.angles - math.radians(bearing_deg)))))
    return float(s.ranges[int(np.argmin(off))])


def far(r: np.ndarray | float) -> bool:
    """Clear as far as the floor is seen: beyond 9 m (the level camera's floor reaches far)."""
    return bool(np.all(np.asarray(r) > 9.0))


def in_view(s: LaserScan, yaw_deg: float = 0.0, margin_deg: float = 2.0) -> np.ndarray:
    """Rays well within a camera's field of view when it looks along ``yaw_deg``."""
    off = np.abs(np.angle(np.exp(1j * (s.angles - math.radians(yaw_deg)))))
    return off < math.radians(HFOV / 2 - margin_deg)


def test_the_floor_is_taken_out_by_the_camera_height() -> None:
    floor = scene(HEIGHT)
    s = scan(floor)
    assert s.angle_increment == pytest.approx(math.radians(1.0))
    # The camera's height said right: the floor is no obstacle, every ray in view is clear.
    assert far(s.ranges[in_view(s)]), s.ranges[in_view(s)]
    # Said 0.1 m too high, the floor stands 0.1 m above the floor margin: obstacles all round.
    wrong = scan(floor, Mounting(height_m=HEIGHT + 0.1))
    assert np.all(np.isfinite(wrong.ranges[in_view(wrong)]))
    # A kerb lower than the margin (3 cm) is floor; one higher (10 cm) is an obstacle.
    low = scan(scene(HEIGHT, Face(2.0, -3.0, 3.0, 0.0, 0.03)))
    assert far(low.ranges[in_view(low)])
    high = scan(scene(HEIGHT, Face(2.0, -3.0, 3.0, 0.0, 0.10)))
    assert ray(high, 0.0) == pytest.approx(2.0, abs=0.02)


def test_what_passes_over_the_robot_is_no_obstacle() -> None:
    # 3 m ahead, the camera sees up to 1.9 m above the floor.
    overhang = scan(scene(HEIGHT, Face(3.0, -1.0, 1.0, PARAMS.max_height_m + 0.1, 3.0)))
    assert far(overhang.ranges[in_view(overhang)])
    shelf = scan(scene(HEIGHT, Face(3.0, -1.0, 1.0, PARAMS.max_height_m - 0.2, 3.0)))
    assert ray(shelf, 0.0) == pytest.approx(3.0, abs=0.02)


@pytest.mark.parametrize("bearing_deg", [-20.0, 0.0, 12.0])
def test_an_obstacle_appears_at_its_range_and_bearing(bearing_deg: float) -> None:
    s = scan(scene(HEIGHT, at_bearing(2.5, bearing_deg)))
    expected = 2.5 / math.cos(math.radians(bearing_deg))  # a flat face: farther off-axis
    assert ray(s, bearing_deg) == pytest.approx(expected, rel=0.02)
    # Left is counter-clockwise positive (REP 103): the other side of the view is clear.
    assert far(ray(s, -bearing_deg - 15.0 if bearing_deg >= 0 else 15.0))
    hits = s.angles[s.ranges < 9.0]
    assert np.degrees(hits).mean() == pytest.approx(bearing_deg, abs=1.5)


def test_rays_outside_the_field_of_view_are_unknown_not_clear() -> None:
    s = scan(scene(HEIGHT))
    outside = np.abs(s.angles) > math.radians(HFOV / 2 + 1.0)
    assert np.all(np.isnan(s.ranges[outside]))
    # Nothing seen in a part of the view (a hole: no reading at all) is unknown: blocked.
    holed = scene(HEIGHT)
    holed[:, 300:340] = np.nan
    assert ray(scan(holed), 0.0) == pytest.approx(MIN_NEAR_M, abs=1e-3)  # the nearest it could be


@pytest.mark.parametrize("yaw_deg", [90.0, 180.0, -45.0])
def test_the_mounting_yaw_turns_the_scan(yaw_deg: float) -> None:
    depth = scene(HEIGHT, at_bearing(2.0, 10.0))
    s = scan(depth, Mounting(height_m=HEIGHT, yaw_deg=yaw_deg))
    expected = 2.0 / math.cos(math.radians(10.0))
    assert ray(s, yaw_deg + 10.0) == pytest.approx(expected, rel=0.02)
    assert math.isnan(ray(s, 0.0)) if abs(yaw_deg) > HFOV / 2 + 1 else True
    assert np.all(np.isnan(s.ranges[~in_view(s, yaw_deg, -1.0)]))


def test_the_mounting_position_moves_the_scan_to_the_base_centre() -> None:
    depth = scene(HEIGHT, at_bearing(2.0, 0.0))
    s = scan(depth, Mounting(x_m=0.3, height_m=HEIGHT))
    assert ray(s, 0.0) == pytest.approx(2.3, abs=0.02)
    left = scan(depth, Mounting(y_m=0.5, height_m=HEIGHT))  # 2 m ahead, 0.5 m left
    assert ray(left, math.degrees(math.atan2(0.5, 2.0))) == pytest.approx(
        math.hypot(2.0, 0.5), abs=0.03
    )


def test_a_camera_of_unknown_height_gives_no_scan() -> None:
    assert not usable(Mounting(height_m=0.0))
    with pytest.raises(ValueError, match="height above the floor is unknown"):
        scan(scene(HEIGHT), Mounting(height_m=0.0))


def test_scans_merge_nearest_first_and_unknown_only_where_none_sees() -> None:
    front = scan(scene(HEIGHT, at_bearing(3.0, 0.0)))
    rear = scan(scene(HEIGHT, at_bearing(1.0, 0.0)), Mounting(height_m=HEIGHT, yaw_deg=180.0))
    near = scan(scene(HEIGHT, at_bearing(1.5, 0.0)))
    merged = merge([front, rear])
    assert ray(merged, 0.0) == pytest.approx(3.0, rel=0.02)
    assert ray(merged, 180.0) == pytest.approx(1.0, rel=0.02)
    assert math.isnan(ray(merged, 90.0))  # seen by neither
    assert ray(merge([front, near]), 0.0) == pytest.approx(1.5, rel=0.02)
    clear = scan(scene(HEIGHT))
    assert far(ray(merge([clear, rear]), 10.0))  # clear and not looked at: clear


def test_only_cameras_looking_ahead_must_be_fresh() -> None:
    assert looks_ahead(Mounting(yaw_deg=0.0), HFOV, 30.0)
    assert looks_ahead(Mounting(yaw_deg=40.0), HFOV, 30.0)  # its field reaches 10 deg
    assert not looks_ahead(Mounting(yaw_deg=50.0), HFOV, 30.0)
    assert not looks_ahead(Mounting(yaw_deg=180.0), HFOV, 30.0)
    front = scan(scene(HEIGHT, at_bearing(2.0, 0.0)))
    mount = Mounting(height_m=HEIGHT)
    fresh = DepthCamera(mount, HFOV, front, 0.1)
    rear = DepthCamera(dataclasses.replace(mount, yaw_deg=180.0), HFOV, None)
    seen = depth_obstacles({"front": fresh, "rear": rear}, 0.5, 30.0)
    assert seen.scan is not None and seen.age_s == 0.1 and seen.missing == ""
    assert sector_clearance(seen.scan, 30.0, 0.3) == pytest.approx(2.0, rel=0.02)
    stale = depth_obstacles({"front": dataclasses.replace(fresh, age_s=0.6)}, 0.5, 30.0)
    assert stale.scan is None and stale.missing == "no recent depth from front (0.60 s)"
    none_yet = depth_obstacles({"front": dataclasses.replace(fresh, scan=None)}, 0.5, 30.0)
    assert none_yet.scan is None and none_yet.missing == "no depth from front yet"
    behind = depth_obstacles({"rear": rear}, 0.5, 30.0)
    assert behind.scan is None and behind.missing == "no depth camera looks ahead"
    unknown = DepthCamera(Mounting(height_m=0.0), HFOV, None)
    said = depth_obstacles({"front": unknown}, 0.5, 30.0).missing
    assert said == "no depth camera looks ahead (front: height above the floor unknown)"


def test_the_controller_reads_the_depth_stages_distance_column() -> None:
    assert DISTANCE_COLUMN == DISTANCE
