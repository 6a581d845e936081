"""Issue 38's per-frame rules of the virtual scan, each on the case that broke it: a drop-off
is a hazard at its edge (the last floor seen), not where the ray meets the lower floor; floor
that must be seen and is not is not clear (an all-far image, a column with no floor at all);
no reading in view is never clear, and a hole between two floor readings is unknown from
where the floor was last seen."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from common.messages import DepthFrame, Header
from depthscan.frame import ScanParams, sample_frame, sample_metres
from depthscan.observe import Observation, observe, virtual_scan
from perception.depth import Mounting
from services.controller.geometry import sector_clearance
from tests.unit.depthscan.depth_scenes import INTR, Face, at_bearing, scene

HEADER = Header(stamp_ns=1_000, frame_id="camera", seq=1, source="test")
PARAMS = ScanParams()
HEIGHT = 0.6
LEVEL = Mounting(height_m=HEIGHT)
SECTOR, HALF_WIDTH = 30.0, 0.3
RANGE_MIN = 0.3


def ahead(depth: np.ndarray, **kw: Any) -> float:
    s = virtual_scan(depth, INTR, LEVEL, PARAMS, HEADER, 10.0, range_min_m=RANGE_MIN, **kw)
    return sector_clearance(s, SECTOR, HALF_WIDTH)


def seen(depth: np.ndarray) -> Observation:
    return observe(sample_metres(depth, PARAMS.stride_px), INTR, LEVEL, PARAMS, HEADER, 10.0,
                   RANGE_MIN)  # fmt: skip


def step(edge_m: float, depth_m: float) -> np.ndarray:
    """The floor, ``depth_m`` lower beyond ``edge_m`` ahead (a kerb, a step down)."""
    upper, lower = scene(HEIGHT), scene(HEIGHT + depth_m)
    return np.where(upper < edge_m, upper, lower)


@pytest.mark.parametrize("depth_m", [0.15, 0.5])
def test_a_drop_off_is_a_hazard_at_its_edge(depth_m: float) -> None:
    # Before the fix the kerb read clear to 2.55 m once its edge was in the blind zone, and
    # the step to where the ray meets the lower floor.
    assert ahead(step(3.0, depth_m)) == pytest.approx(3.0, abs=0.12)
    edges = seen(step(3.0, depth_m)).hazards
    straight = edges[np.abs(edges[:, 1]) < 0.3]
    assert straight[:, 0].min() == pytest.approx(3.0, abs=0.12)
    assert straight[:, 0].max() <= 3.0


@pytest.mark.parametrize("depth_m", [0.15, 0.5])
def test_an_edge_inside_the_blind_zone_blocks_at_the_nearest_range(depth_m: float) -> None:
    # The camera sees the floor from 1.39 m: an edge at 1.0 m shows only the lower floor.
    assert ahead(step(1.0, depth_m)) == pytest.approx(RANGE_MIN, abs=0.01)
    assert len(seen(step(1.0, depth_m)).unknown) > 0


def test_an_image_with_no_floor_at_all_is_not_clear() -> None:
    # "Bottomless": every pixel 65535 mm, no range stated; and every pixel 10 m in 0.3-10 m.
    for mm, top in ((65535, 0.0), (10000, 10.0)):
        frame = DepthFrame(
            header=HEADER, encoding="16UC1", width=INTR.width, height=INTR.height,
            data=np.full((INTR.height, INTR.width), mm, "<u2").tobytes(), fx=INTR.fx,
            fy=INTR.fy, cx=INTR.cx, cy=INTR.cy, range_min_m=RANGE_MIN, range_max_m=top,
        )  # fmt: skip
        o = observe(sample_frame(frame, PARAMS.stride_px), INTR, LEVEL, PARAMS, HEADER, top,
                    RANGE_MIN)  # fmt: skip
        assert sector_clearance(o.scan, SECTOR, HALF_WIDTH) == pytest.approx(RANGE_MIN, abs=0.01)


def test_a_black_box_in_the_blind_zone_blocks() -> None:
    # 0.5 m tall, 1 m ahead, no readings on it: the floor beyond is seen above it.
    depth = scene(HEIGHT, Face(1.0, -0.3, 0.3, 0.0, 0.5))
    depth[depth == np.float32(1.0)] = np.nan
    assert ahead(scene(HEIGHT)) > 9.0
    assert ahead(depth) == pytest.approx(RANGE_MIN, abs=0.01)  # was 9.9 m: clear


def test_a_dark_pole_beside_the_nose_blocks_the_corridor() -> None:
    # 0.45 m ahead at 25 deg (0.21 m to the side, inside the 0.6 m corridor): no reading on
    # it. It blocks where a reading would have put it, and with none it blocks too.
    pole = at_bearing(0.45, 25.0, 0.02)
    assert ahead(scene(HEIGHT, pole)) < 0.5
    depth = scene(HEIGHT, pole)
    depth[depth == np.float32(0.45)] = np.nan
    clearance = ahead(depth)
    assert clearance < 0.5, clearance  # was inf: the corridor skipped the zero-range rays


def test_a_hole_between_two_floor_readings_is_unknown_from_the_last_floor() -> None:
    # Rows that see the floor from 2.0 to 2.6 m read nothing (a dark mat, a low dark thing).
    depth = scene(HEIGHT)
    z = scene(HEIGHT)
    depth[(z > 2.0) & (z < 2.6)] = np.nan
    assert ahead(depth) == pytest.approx(2.0, abs=0.05)  # was 9.9: clear beyond
    unknown = seen(depth).unknown
    straight = unknown[np.abs(unknown[:, 1]) < 0.05]
    assert straight[:, 0].min() == pytest.approx(2.0, abs=0.05)
    assert straight[:, 0].max() == pytest.approx(2.6, abs=0.05)


def test_single_missing_samples_are_not_holes() -> None:
    # 1 % of pixels read nothing at random (a stereo camera's speckle): still clear far.
    depth = scene(HEIGHT)
    rng = np.random.default_rng(1)
    depth[rng.random(depth.shape) < 0.01] = np.nan
    assert ahead(depth) > 9.0
    assert len(seen(depth).unknown) == 0


def test_floor_and_hazards_are_where_the_camera_saw_them() -> None:
    o = seen(scene(HEIGHT, Face(2.5, -0.2, 0.2, 0.0, 0.3)))
    box = o.hazards[np.abs(o.hazards[:, 1]) < 0.2]
    assert box[:, 0].min() == pytest.approx(2.5, abs=0.01)
    assert o.floor[:, 0].min() == pytest.approx(HEIGHT / math.tan(math.radians(23.413)),
                                                abs=0.05)  # fmt: skip


def test_a_hole_along_a_near_things_edge_is_that_things_edge() -> None:
    # A box 1 m ahead filling the bottom of the image, and a stereo camera's band of no
    # readings 12 px wide along its left edge: blocked at the box, not at the minimum range.
    depth = scene(HEIGHT, Face(1.0, -0.3, 0.3, 0.0, 0.5))
    cols = np.flatnonzero(np.isclose(depth[-1], 1.0))
    depth[:, cols[0] - 12 : cols[0]] = np.nan
    assert ahead(depth) == pytest.approx(1.0, abs=0.02)
    # A dark thing with floor on both sides of it is not taken for an edge.
    dark = scene(HEIGHT, Face(1.0, -0.3, 0.3, 0.0, 0.5))
    dark[dark == np.float32(1.0)] = np.nan
    assert ahead(dark) == pytest.approx(RANGE_MIN, abs=0.01)


def test_a_thing_filling_the_bottom_reads_at_its_range_from_a_camera_ahead_of_the_base() -> None:
    # The camera 0.2 m ahead of the base's centre, a person-like face 1 m ahead of it filling
    # the bottom of the image: the ray reads 1.2 m from the base, not the minimum range.
    mount = Mounting(x_m=0.2, height_m=HEIGHT)
    depth = scene(HEIGHT, Face(1.0, -0.3, 0.3, 0.0, 1.7))
    s = virtual_scan(depth, INTR, mount, PARAMS, HEADER, 10.0, range_min_m=RANGE_MIN)
    assert sector_clearance(s, SECTOR, HALF_WIDTH) == pytest.approx(1.2, abs=0.05)


def _dropped(depth: np.ndarray, rows: tuple[int, ...], cols: tuple[int, ...]) -> np.ndarray:
    out = depth.copy()
    out[np.ix_(rows, cols)] = np.nan
    return out


def test_pixels_dropped_here_and_there_are_no_hole_but_a_hole_three_pixels_wide_is() -> None:
    """The case a live run caught (a depth-only follower stood blocked for good): a stereo
    camera's scattered dropped pixels fell on three of one column's samples at the bottom of
    the image (rows 470, 474, 478 of column 318), which read as a hole of hole_px where the
    floor must show: blocked at the camera's nearest range. Filled from its row's neighbours,
    each reads the floor; three pixels wide, the same hole still blocks, from the raw frame
    as from metres."""
    floor = scene(HEIGHT)
    assert ahead(floor) > 9.0
    sampled = (470, 474, 478)
    speckled = _dropped(floor, sampled, (318,))
    assert ahead(speckled) > 9.0
    assert seen(speckled).unknown.size == 0
    hole = _dropped(floor, sampled, (317, 318, 319))
    assert ahead(hole) == pytest.approx(RANGE_MIN, abs=0.02)

    def from_frame(depth: np.ndarray) -> float:
        mm = np.nan_to_num(np.round(depth * 1000), nan=0).astype("<u2")
        frame = DepthFrame(header=HEADER, encoding="16UC1", width=INTR.width, height=INTR.height,
                           data=mm.tobytes(), fx=INTR.fx, fy=INTR.fy, cx=INTR.cx, cy=INTR.cy,
                           range_min_m=RANGE_MIN, range_max_m=10.0)  # fmt: skip
        s = observe(sample_frame(frame, PARAMS.stride_px), INTR, LEVEL, PARAMS, HEADER, 10.0,
                    RANGE_MIN).scan  # fmt: skip
        return sector_clearance(s, SECTOR, HALF_WIDTH)

    # (The frame's floor ends where it passes 10 m, its stated range: clear as far as that.)
    assert from_frame(speckled) == from_frame(floor) > 1.5
    assert from_frame(hole) == pytest.approx(RANGE_MIN, abs=0.02)


def test_one_percent_of_pixels_dropped_at_random_never_blocks_an_empty_floor() -> None:
    rng = np.random.default_rng(0)
    floor = scene(HEIGHT)
    for _ in range(50):
        depth = floor.copy()
        depth[rng.random(depth.shape) < 0.01] = np.nan
        assert ahead(depth) > 9.0
