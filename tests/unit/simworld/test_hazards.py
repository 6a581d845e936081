"""The simulator's hazards (issue 38): obstacles with a height and a material, a laser with a
height, drop-offs in the floor, and how a run near them is scored."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.messages import GroundTruth, Header
from services.controller.contract import ControllerSettings
from simworld.depth import floor_depth, render_depth
from simworld.laser import LaserSpec, cast
from simworld.render import DARK_BGR, CameraSpec, background, layout, render
from simworld.scenarios import HAZARDS, SCENARIOS, card
from simworld.world import Drop, Material, Obstacle, Robot, World
from tools.scenarios.score import HAZARD_MARGIN_M, ScenarioLog, score, verdict

SPEC = CameraSpec(width=320, height=240, hfov_deg=60.0, height_m=0.6)
HDR = Header(stamp_ns=1, frame_id="world", seq=0, source="sim")
ALICE = card("alice", (0.0, 6.5, 0.0))


def _box_rows(spec: CameraSpec, z: float, height_m: float) -> tuple[int, int]:
    """The rows (top, bottom) a box ``height_m`` tall with its centre ``z`` ahead spans."""
    f, cy = spec.focal_px, spec.height / 2
    return round(cy + f * (spec.height_m - height_m) / z), round(cy + f * spec.height_m / z)


def test_positional_obstacle_is_a_solid_half_metre_box_and_material_names_are_checked() -> None:
    ob = Obstacle(2.0, 0.5, 0.3)
    assert (ob.height_m, ob.material) == (0.5, Material.SOLID)
    assert Obstacle(1, 0, 0.1, material="glass").material is Material.GLASS  # type: ignore[arg-type]
    assert Obstacle(1, 0, 0.1, material="mirror").material is Material.MIRROR  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        Obstacle(1, 0, 0.1, material="velvet")  # type: ignore[arg-type]


def test_an_obstacle_is_drawn_at_its_own_height_in_colour_and_depth() -> None:
    for height in (0.15, 0.5, 1.2):
        world = World(Robot(), obstacles=[Obstacle(2.0, 0.0, 0.3, height_m=height)])
        (placed,) = layout(world, SPEC)
        assert placed.height_m == height
        top, bottom = _box_rows(SPEC, 2.0, height)
        assert placed.rect is not None and (placed.rect[1], placed.rect[3]) == (top, bottom + 1)
        col = SPEC.width // 2
        depth = render_depth(world, SPEC)
        assert depth[top:bottom, col] == pytest.approx(1.7)  # its front face
        assert depth[top - 2, col] != pytest.approx(1.7)  # above it: not the box


def test_dark_and_glass_faces_read_nothing_and_solid_reads_its_face() -> None:
    col = SPEC.width // 2
    top, bottom = _box_rows(SPEC, 2.0, 0.5)
    faces = {}
    for material in Material:
        world = World(Robot(), obstacles=[Obstacle(2.0, 0.0, 0.3, material=material)])
        faces[material] = render_depth(world, SPEC)[top + 1 : bottom, col]
    assert faces[Material.SOLID] == pytest.approx(1.7)
    assert np.isnan(faces[Material.DARK]).all()
    assert np.isnan(faces[Material.GLASS]).all()


def test_dark_is_drawn_near_black_and_glass_shows_what_is_behind_it() -> None:
    col = SPEC.width // 2
    top, bottom = _box_rows(SPEC, 2.0, 0.5)
    mid = (top + bottom) // 2
    dark = render(World(Robot(), obstacles=[Obstacle(2.0, 0, 0.3, material="dark")]), SPEC)  # type: ignore[arg-type]
    assert tuple(dark[mid, col]) == DARK_BGR
    behind = World(Robot(), targets=[ALICE])
    pane = World(Robot(), obstacles=[Obstacle(2.0, 0, 0.3, 1.0, Material.GLASS)], targets=[ALICE])
    clear, through = render(behind, SPEC), render(pane, SPEC)
    # Through the pane the image differs from the clear view by a faint tint alone.
    diff = np.abs(through.astype(int) - clear.astype(int))
    assert diff[top:bottom, col - 5 : col + 5].max() <= 30
    assert diff[top:bottom, col - 5 : col + 5].max() > 0  # but it is there


def test_the_laser_sees_only_what_is_taller_than_its_plane_and_not_glass() -> None:
    world = World(
        Robot(),
        obstacles=[
            Obstacle(2.0, 0.0, 0.3, height_m=0.15),  # under the plane
            Obstacle(3.0, 0.0, 0.3, height_m=1.0, material=Material.GLASS),
            Obstacle(4.0, 0.0, 0.3, height_m=0.5, material=Material.DARK),  # seen: it is dark
        ],
        drops=[Drop(1.0, -5.0, 20.0, 5.0, 0.5)],  # never seen
    )
    spec = LaserSpec(rays=361, fov_deg=180.0, noise_std_m=0.0, height_m=0.2)
    ahead = spec.rays // 2
    ranges = cast((0.0, 0.0, 0.0), world.laser_circles(spec.height_m), spec)
    assert ranges[ahead] == pytest.approx(3.7)  # the dark box's near side
    # A laser on a mast over the low box still sees the dark one; one under 0.15 m sees the box.
    assert world.laser_circles(0.6).shape == (0, 3)
    low = cast((0.0, 0.0, 0.0), world.laser_circles(0.1), spec)
    assert low[ahead] == pytest.approx(1.7)


def _kerb_pixels(world: World, spec: CameraSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The column through the camera's centre: the flat floor's z, and the depth drawn."""
    col = spec.width // 2
    return floor_depth(spec)[:, col], render_depth(world, spec)[:, col], np.arange(spec.height)


def test_beyond_a_drop_the_floor_reads_the_lower_floor_along_the_same_ray() -> None:
    depth_m, h = 0.5, SPEC.height_m
    world = World(Robot(), drops=[Drop(3.0, -5.0, 20.0, 5.0, depth_m)])
    flat, drawn, rows = _kerb_pixels(world, SPEC)
    below = rows >= SPEC.height // 2
    beyond = below & (flat > 3.0) & (flat < 20.0)  # the drop ends 20 m ahead
    before = below & (flat < 3.0)
    assert beyond.any() and before.any()
    np.testing.assert_allclose(drawn[beyond], flat[beyond] * (h + depth_m) / h, rtol=1e-6)
    np.testing.assert_array_equal(drawn[before], flat[before])
    assert np.isnan(drawn[~below]).all()
    # Away to the side of the drop the floor is flat.
    side = render_depth(World(Robot(), drops=[Drop(3.0, 5.0, 20.0, 9.0, depth_m)]), SPEC)
    np.testing.assert_array_equal(side[:, SPEC.width // 2], flat)


def test_a_drop_is_placed_by_the_robots_pose_and_the_cameras_mount() -> None:
    """The same kerb ahead of the camera, whichever way the robot and the camera face."""
    kerb = 0.15
    ahead = World(Robot(), drops=[Drop(3.0, -5.0, 20.0, 5.0, kerb)])
    reference = render_depth(ahead, SPEC)
    # The robot at (1, 2) facing +y, the camera turned round: it looks along -y, and the kerb
    # is 3 m that way, from y = -1 on.
    rear = CameraSpec(SPEC.width, SPEC.height, SPEC.hfov_deg, SPEC.height_m, 180.0)
    turned = World(
        Robot(x=1.0, y=2.0, theta=math.pi / 2), drops=[Drop(-4.0, -20.0, 6.0, -1.0, kerb)]
    )
    np.testing.assert_allclose(render_depth(turned, rear), reference, rtol=1e-5)


def test_the_lower_floor_is_darker_in_colour_but_not_dark_and_things_cover_it() -> None:
    world = World(Robot(), drops=[Drop(3.0, -5.0, 20.0, 5.0, 0.5)])
    flat, _, rows = _kerb_pixels(world, SPEC)
    image, empty = render(world, SPEC), background(SPEC)
    col = SPEC.width // 2
    beyond = (rows >= SPEC.height // 2) & (flat > 3.0) & (flat < 20.0)
    assert (image[beyond, col] < empty[beyond, col]).all()
    assert image[beyond, col].min() > 30 * 2  # well above sim.depth_dark_level
    assert (image[~beyond, col] == empty[~beyond, col]).all()
    # A person standing beyond the edge is drawn over the lower floor, at their own depth.
    with_alice = World(Robot(), drops=world.drops, targets=[ALICE])
    depth = render_depth(with_alice, SPEC)
    assert np.isclose(depth[:, col], 6.25).any()


def test_without_drops_the_floor_is_the_cached_flat_one() -> None:
    np.testing.assert_array_equal(render_depth(World(Robot()), SPEC), floor_depth(SPEC))


def _truth(x: float, t: float = 1.0) -> GroundTruth:
    return GroundTruth(
        header=HDR,
        sim_time_s=t,
        robot=(x, 0.0, 0.0),
        targets_xy=np.array([[6.5, 0.0]]),
        target_names=("person",),
        target_ids=("alice",),
    )


@pytest.mark.parametrize(
    ("x", "edge", "passed"), [(2.5, 0.25, True), (2.9, -0.15, False), (3.2, -0.45, False)]
)
def test_edge_clearance_is_from_the_robots_circle_and_over_the_edge_fails(
    x: float, edge: float, passed: bool
) -> None:
    sc = SCENARIOS["kerb"]
    world = sc.build()
    result = score(
        sc, ScenarioLog(truths=[_truth(0.5), _truth(x, 2.0)]), world, ControllerSettings(), 60.0
    )
    assert result["min_edge_clearance_m"] == pytest.approx(edge)
    assert result["min_clearance_m"] is None
    assert result["checks"]["never over an edge"] is passed
    assert result["success"] is passed


def test_no_drops_no_edge_figure_and_no_edge_check() -> None:
    sc = SCENARIOS["obstacle"]
    result = score(sc, ScenarioLog(truths=[_truth(1.0)]), sc.build(), ControllerSettings(), 60.0)
    assert result["min_edge_clearance_m"] is None
    assert "never over an edge" not in result["checks"]


def test_hazard_obstacle_rule_is_the_safety_distance_less_the_margin() -> None:
    s = ControllerSettings()
    sc = SCENARIOS["low_box"]
    base = score(sc, ScenarioLog(truths=[_truth(1.0)]), sc.build(), s, 60.0)
    rule = "never nearer an obstacle than the safety distance less the margin"
    for clearance, holds in ((s.safety_distance_m - HAZARD_MARGIN_M + 0.01, True),
                             (s.safety_distance_m - HAZARD_MARGIN_M - 0.01, False)):  # fmt: skip
        ok, checks = verdict(sc, {**base, "min_clearance_m": clearance}, s, 60.0)
        assert checks[rule] is holds
        assert not holds or not ok  # the stricter existing rule still stands: not weakened
        assert not checks["kept the safety distance"]
    ok, checks = verdict(sc, {**base, "min_clearance_m": s.safety_distance_m}, s, 60.0)
    assert ok and checks[rule]
    # A scenario that must reach its target is not a hazard scenario: no such rule.
    ahead = SCENARIOS["ahead"]
    _, checks = verdict(ahead, {**base, "min_clearance_m": 1.0}, s, 60.0)
    assert rule not in checks


def test_each_hazard_scenario_puts_one_hazard_ahead_and_alice_beyond_it() -> None:
    near = {"black_box_near", "dark_pole_near"}  # in the depth camera's blind zone at start
    assert {sc.name for sc in HAZARDS} == {
        "low_box", "kerb", "step", "black_box", "dark_pole", "glass", *near
    }  # fmt: skip
    for sc in HAZARDS:
        world = sc.build()
        assert not sc.must_reach and sc.controller == {"distance_source": "box"}
        assert len(world.obstacles) + len(world.drops) == 1
        (alice,) = world.targets
        hazard_x = min([o.x for o in world.obstacles] + [d.x0 for d in world.drops])
        assert (0.5 if sc.name in near else 2.0) < hazard_x < alice.position(0.0)[0]
        # Never nearer than the safety distance at the start: the run judges the robot.
        assert world.clearance() + world.robot.radius >= 0.5
        assert sc.duration_s >= 40.0
