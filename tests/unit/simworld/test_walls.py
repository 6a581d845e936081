"""Walls (issue 41): a straight wall is seen by the laser, drawn in perspective in colour and
depth, hides what is behind it, and counts as an obstacle for the scenario's clearance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.messages import GroundTruth, Header
from services.controller.contract import ControllerSettings
from simworld.depth import floor_depth, owners, render_depth, targets_in_camera
from simworld.faults import mirror_reads
from simworld.laser import LaserSpec, cast
from simworld.render import CameraSpec, render
from simworld.scenarios import Scenario, card, person
from simworld.walls import DARK_WALL_BGR, wall_view
from simworld.world import Material, Obstacle, Robot, Wall, World
from tools.scenarios.score import ScenarioLog, score

SPEC = CameraSpec(width=320, height=240, hfov_deg=60.0, height_m=0.6)
LASER = LaserSpec(noise_std_m=0.0)
HDR = Header(stamp_ns=1, frame_id="world", seq=0, source="sim")


def _ranges(world: World, pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    h = LASER.height_m
    return cast(pose, world.laser_circles(h), LASER, segments=world.laser_walls(h))


def _ray(angle_rad: float) -> int:
    return round((angle_rad - LASER.angle_min) / LASER.angle_increment)


def test_the_laser_hits_a_wall_at_its_range_along_every_ray() -> None:
    world = World(Robot(), walls=[Wall(3.0, -4.0, 3.0, 4.0)])
    r = _ranges(world)
    for deg in (0.0, 20.0, -35.0, 50.0):
        a = LASER.angle_min + _ray(math.radians(deg)) * LASER.angle_increment
        assert r[_ray(math.radians(deg))] == pytest.approx(3.0 / math.cos(a), abs=1e-4)
    assert np.isinf(r[_ray(math.radians(-120.0))])  # behind: the wall is ahead only
    # A turned robot, a slanted wall: the ray straight ahead meets it where geometry says.
    slanted = World(Robot(), walls=[Wall(2.0, -1.0, 4.0, 1.0)])  # meets y=0 at x=3
    assert _ranges(slanted, (0.0, 0.0, 0.0))[_ray(0.0)] == pytest.approx(3.0, abs=1e-4)
    assert _ranges(slanted, (3.0, -2.0, math.pi / 2))[_ray(0.0)] == pytest.approx(2.0, abs=1e-4)


def test_the_laser_sees_no_glass_wall_and_no_wall_under_its_plane() -> None:
    world = World(
        Robot(),
        walls=[
            Wall(2.0, -1.0, 2.0, 1.0, material=Material.GLASS),
            Wall(3.0, -1.0, 3.0, 1.0, height_m=0.15),
            Wall(5.0, -1.0, 5.0, 1.0, material=Material.DARK),
        ],
    )
    assert _ranges(world)[_ray(0.0)] == pytest.approx(5.0, abs=1e-4)  # the dark one stops it


def test_a_wall_pixel_reads_the_depth_of_its_point_on_the_wall() -> None:
    # A wall slanted across the view: each column reads the depth (along the optical axis)
    # where its ray meets the wall, constant down the column, between floor and top.
    wall = Wall(2.0, 2.0, 5.0, -2.0, height_m=1.5)
    world = World(Robot(), walls=[wall])
    depth = render_depth(world, SPEC)
    f, cx, cy = SPEC.focal_px, SPEC.width / 2, SPEC.height / 2
    for u in (40, 160, 240):
        k = (cx - u - 0.5) / f  # lateral per metre ahead
        # The wall's line: x = 2 + 3 s, y = 2 - 4 s; the ray: y = k x.
        s = (2 - 2 * k) / (4 + 3 * k)
        z = 2 + 3 * s
        top = cy - (wall.height_m - SPEC.height_m) * f / z
        bottom = cy + SPEC.height_m * f / z
        rows = np.arange(math.ceil(top), math.floor(bottom - 0.5))
        assert np.allclose(depth[rows, u], z, rtol=1e-5)
        above = math.floor(top - 1.5)
        assert not np.isfinite(depth[above, u])  # the empty wall at infinity, above it
        below = math.ceil(bottom + 1)
        assert depth[below, u] == pytest.approx(floor_depth(SPEC)[below, u])  # the floor
        assert depth[below, u] < z  # in front of the wall's foot
    assert wall.distance(0.0, 0.0) == pytest.approx(14 / 5)  # |4x + 3y - 14| / 5


def test_a_wall_is_drawn_in_colour_over_its_pixels_and_a_dark_one_reads_nothing() -> None:
    solid = World(Robot(), walls=[Wall(3.0, -3.0, 3.0, 3.0)])
    view = wall_view(solid, SPEC)
    assert view is not None
    img = render(solid, SPEC)
    assert np.array_equal(img[view.opaque], view.colour[view.opaque])
    dark = World(Robot(), walls=[Wall(3.0, -3.0, 3.0, 3.0, material=Material.DARK)])
    dark_view = wall_view(dark, SPEC)
    assert dark_view is not None
    # Shaded by its angle, never brighter than its colour: below the dark-dropout level (30).
    assert render(dark, SPEC)[dark_view.opaque].max() <= max(DARK_WALL_BGR) < 30
    assert not np.isfinite(render_depth(dark, SPEC)[dark_view.opaque]).any()


def test_a_person_behind_a_wall_is_hidden_and_one_in_front_is_not() -> None:
    alice = person("alice", (0, 5.0, 0.0))
    behind = World(Robot(), walls=[Wall(3.0, -2.0, 3.0, 2.0)], targets=[alice])
    assert targets_in_camera(behind, SPEC) == []
    owner, _ = owners(behind, SPEC)
    assert (owner == -1).all()
    depth = render_depth(behind, SPEC)
    assert np.nanmax(depth[: SPEC.height // 2]) == pytest.approx(3.0, abs=1e-4)  # the wall only
    in_front = World(Robot(), walls=[Wall(6.0, -2.0, 6.0, 2.0)], targets=[alice])
    ((tid, *_),) = targets_in_camera(in_front, SPEC, min_visible=0.9)
    assert tid == "alice"
    # Half behind a wall's end: part of her shows, part is hidden.
    half = World(Robot(), walls=[Wall(3.0, 0.0, 3.0, 2.0)], targets=[alice])
    owner, _ = owners(half, SPEC)
    seen = owner == 0
    assert seen.any() and not seen[:, : SPEC.width // 2].any()
    # A glass wall hides her from neither the colour image nor the owners; her depth is lost.
    glass = World(Robot(), walls=[Wall(3.0, -2.0, 3.0, 2.0, material=Material.GLASS)],
                  targets=[alice])  # fmt: skip
    assert [t[0] for t in targets_in_camera(glass, SPEC)] == ["alice"]
    assert not np.isfinite(render_depth(glass, SPEC)[: SPEC.height // 2 + 20]).any()


def test_a_box_behind_a_wall_is_hidden_in_colour_and_depth_and_its_mirror_reading_too() -> None:
    mirror = Obstacle(5.0, 0.0, 0.3, height_m=0.5, material=Material.MIRROR)
    open_world = World(Robot(), obstacles=[mirror])
    walled = World(Robot(), obstacles=[mirror], walls=[Wall(3.0, -2.0, 3.0, 2.0, height_m=2.0)])
    for world in (open_world, walled):
        truth = render_depth(world, SPEC)
        read = mirror_reads(world, SPEC, truth, 2.0)
        changed = np.isfinite(truth) & (read != truth)
        assert changed.any() == (world is open_world)
    assert np.array_equal(render(walled, SPEC), render(World(Robot(), walls=walled.walls), SPEC))


def test_a_world_without_walls_draws_as_before() -> None:
    # The no-wall path is the old one: nothing of a wall view is made.
    world = World(Robot(), obstacles=[Obstacle(3.0, 0.5, 0.3)], targets=[card("a", (0, 5, 0))])
    assert wall_view(world, SPEC) is None


def test_a_wall_counts_in_the_clearance_and_the_scenario_score() -> None:
    wall = Wall(1.0, -2.0, 1.0, 2.0)
    world = World(Robot(), walls=[wall], targets=[card("alice", (0, 4.0, 0.0))])
    assert world.clearance() == pytest.approx(1.0 - world.robot.radius)
    truth = GroundTruth(header=HDR, sim_time_s=1.0, robot=(0.6, 0.0, 0.0),
                        targets_xy=np.array([[4.0, 0.0]]), target_names=("person",),
                        target_ids=("alice",))  # fmt: skip
    sc = Scenario("w", "", lambda: world, 10.0, must_reach=False)
    result = score(sc, ScenarioLog(truths=[truth]), world, ControllerSettings(), 60.0)
    assert result["min_clearance_m"] == pytest.approx(0.4)
    assert result["checks"]["kept the safety distance"] is False  # 0.4 < 0.5


def test_a_mirror_wall_and_a_wall_of_no_length_are_refused() -> None:
    with pytest.raises(ValueError):
        Wall(0, 0, 1, 0, material=Material.MIRROR)
    with pytest.raises(ValueError):
        Wall(1, 1, 1, 1)
    assert Wall(0, 0, 1, 0, material="dark").material is Material.DARK  # type: ignore[arg-type]
