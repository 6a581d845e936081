"""The depth cameras' short memory (depthscan/local_map.py): what was seen stays
until its place is seen clear, a low box that slips into the blind zone stays an obstacle, the
blind zone at start-up is not known clear, and the map moves with the robot's commands."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.messages import Header, LaserScan
from common.odometry import Odometry
from common.unicycle import advance
from depthscan.frame import ScanParams, sample_metres
from depthscan.local_map import (
    FREE,
    HAZARD,
    UNKNOWN,
    UNSEEN,
    LocalMap,
    MapParams,
)
from depthscan.observe import observe
from perception.depth import Mounting
from services.controller.geometry import sector_clearance
from tests.unit.depthscan.depth_scenes import INTR, Face, scene

HEADER = Header(stamp_ns=1_000, frame_id="camera", seq=1, source="test")
PARAMS = ScanParams()
HEIGHT = 0.6
LEVEL = Mounting(height_m=HEIGHT)
SECTOR, HALF_WIDTH = 30.0, 0.3


def look(m: LocalMap, x: float, *faces: Face) -> None:
    """The robot at (x, 0) facing +x sees ``faces`` (placed in its own frame)."""
    depth = scene(HEIGHT, *faces)
    seen = observe(sample_metres(depth, PARAMS.stride_px), INTR, LEVEL, PARAMS, HEADER, 10.0,
                   0.3)  # fmt: skip
    m.observe(seen, (x, 0.0, 0.0))


def box(ahead_m: float, top_m: float = 0.15) -> Face:
    return Face(ahead_m, -0.3, 0.3, 0.0, top_m)


def clear(scan: LaserScan) -> float:
    """The room ahead by the map alone (rays with nothing remembered read +inf: clear)."""
    return sector_clearance(scan, SECTOR, HALF_WIDTH)


def clearance(m: LocalMap, x: float) -> float:
    m.stand((x, 0.0, 0.0))
    return clear(m.read((x, 0.0, 0.0), HEADER).scan)


def test_a_low_box_that_slips_into_the_blind_zone_stays_an_obstacle() -> None:
    m = LocalMap(MapParams())
    for x in np.arange(0.0, 2.1, 0.1):  # the robot drives towards a box 3 m ahead
        look(m, x, box(3.0 - x))
    # At x = 2.1 the box is 0.9 m ahead, lower than any ray the camera has there (0.21 m).
    assert np.isnan(scene(HEIGHT, box(0.9))).sum() == np.isnan(scene(HEIGHT)).sum()
    look(m, 2.1, box(0.9))
    # Remembered: 0.9 m ahead, less the box's corners seen across the corridor and a cell.
    assert 0.8 < clearance(m, 2.1) <= 0.91


def test_what_is_seen_clear_is_forgotten() -> None:
    m = LocalMap(MapParams())
    look(m, 0.0, box(2.5, 0.4))
    assert clearance(m, 0.0) == pytest.approx(2.5, abs=0.05)
    look(m, 0.0)  # the box is taken away: the floor is seen where it stood
    assert clearance(m, 0.0) > 3.9


def test_the_blind_zone_at_start_up_is_not_known_and_is_learnt_by_driving() -> None:
    m = LocalMap(MapParams())
    look(m, 0.0)
    m.stand((0.0, 0.0, 0.0))
    known = m.read((0.0, 0.0, 0.0), HEADER).known_m
    assert 0.25 <= known <= 0.35  # the robot's own footprint, then the unseen blind zone
    for x in np.arange(0.0, 1.5, 0.1):
        look(m, x)
        m.stand((x, 0.0, 0.0))
    assert m.read((1.4, 0.0, 0.0), HEADER).known_m > 2.5  # seen on the way


def test_a_hole_is_remembered_unknown_until_seen() -> None:
    m = LocalMap(MapParams())
    depth = scene(HEIGHT)
    z = scene(HEIGHT)
    depth[(z > 2.0) & (z < 2.6)] = np.nan
    seen = observe(sample_metres(depth, PARAMS.stride_px), INTR, LEVEL, PARAMS, HEADER, 10.0,
                   0.3)  # fmt: skip
    m.observe(seen, (0.0, 0.0, 0.0))
    assert clearance(m, 1.0) == pytest.approx(1.0, abs=0.08)  # 2.0 m from where it was seen


def test_the_map_turns_and_rolls_with_the_robot() -> None:
    m = LocalMap(MapParams(size_m=4.0))
    look(m, 0.0, box(1.5, 0.4))
    # Turned 90 deg left, the box is on the right: not ahead.
    m.stand((0.0, 0.0, math.pi / 2))
    side = m.read((0.0, 0.0, math.pi / 2), HEADER).scan
    assert clear(side) > 3.0
    right = side.ranges[np.abs(side.angles + math.pi / 2) < math.radians(5)]
    assert np.min(right) == pytest.approx(1.5, abs=0.05)
    # Drive 1.5 m away (+y): the window rolls by whole cells and keeps the box.
    m.stand((0.0, 1.5, math.pi / 2))
    assert (m.grid == HAZARD).any()
    behind = m.read((0.0, 1.5, math.pi / 2), HEADER).scan
    back = behind.ranges[np.abs(np.abs(behind.angles) - math.pi * 0.75) < math.radians(10)]
    assert np.min(back) == pytest.approx(math.hypot(1.5, 1.5 - 0.3), abs=0.06)  # its corner
    # Far beyond the window: forgotten (rolled out), the new cells unseen.
    m.stand((0.0, 9.0, 0.0))
    assert not (m.grid == HAZARD).any() and (m.grid == UNSEEN).sum() > (m.grid == FREE).sum()


def test_odometry_integrates_the_commands() -> None:
    odo = Odometry()
    odo.command(10.0, 0.5, 0.0)
    odo.command(12.0, 0.0, math.pi / 4)
    odo.command(14.0, 0.0, 0.0)
    assert odo.pose_at(11.0) == pytest.approx((0.5, 0.0, 0.0))
    assert odo.pose_at(13.0) == pytest.approx((1.0, 0.0, math.pi / 4))
    assert odo.pose_at(20.0) == pytest.approx((1.0, 0.0, math.pi / 2))
    assert odo.pose_at(5.0) == (0.0, 0.0, 0.0)
    # An arc: a quarter circle of radius 1.
    x, y, th = advance((0.0, 0.0, 0.0), 1.0, 1.0, math.pi / 2)
    assert (x, y, th) == pytest.approx((1.0, 1.0, math.pi / 2))


def test_a_map_written_and_taken_back_keeps_its_hazards_not_its_floor() -> None:
    m = LocalMap(MapParams())
    look(m, 0.0, box(2.5, 0.4))
    data = m.dump((0.5, 0.0, 0.1), 123)
    again = LocalMap(MapParams())
    pose, kept, saved_ns = again.restore(data)
    assert pose == (0.5, 0.0, 0.1) and saved_ns == 123
    assert kept == np.count_nonzero(m.grid == HAZARD) + np.count_nonzero(m.grid == UNKNOWN)
    assert (again.grid == HAZARD).sum() == (m.grid == HAZARD).sum()
    assert not (again.grid == FREE).any()  # seen floor is to be seen again
    with pytest.raises(ValueError, match="not a saved depth map"):
        again.restore(b"garbage")
    with pytest.raises(ValueError, match=r"map of 0\.05 m cells, not \(160, 160\) of 0\.1 m"):
        LocalMap(MapParams(resolution_m=0.1, size_m=16.0)).restore(data)
