"""People with a body (simworld/body.py, body_draw.py, people.py): the silhouette in the colour
and depth images, the rounded depth of the torso, facing and gait, the variety of people, the
truth a depth camera is held to, and the flat card of the simple world, unchanged."""

from __future__ import annotations

import hashlib
from dataclasses import replace

import numpy as np
import pytest

from simworld.body import Body, body_for, people
from simworld.depth import floor_depth, owners, render_depth, targets_in_camera
from simworld.render import CameraSpec, background, render
from simworld.scenarios import SCENARIOS, card, person
from simworld.world import Drop, Material, Obstacle, Robot, Target, World, flat_world

SPEC = CameraSpec()  # 640x480, 60 deg, 0.6 m up
F, CX, CY = SPEC.focal_px, SPEC.width / 2, SPEC.height / 2
#: A body in light clothes, facing the camera (the camera looks along +x: facing 180 deg).
LIGHT = Body(height_m=1.75, shoulder_m=0.46, depth_m=0.26, top=(170, 150, 140),
             trousers=(150, 160, 170), facing_deg=180.0)  # fmt: skip


def _one(body: Body, x: float = 3.0, *path: tuple[float, float, float]) -> World:
    waypoints = path or ((0.0, x, 0.0),)
    return World(Robot(), targets=[person("p", *waypoints, body=body)])


def _row(world: World, height_m: float, x: float = 3.0) -> int:
    """The image row that sees ``height_m`` above the floor at ``x`` ahead."""
    return int(CY + F * (SPEC.height_m - height_m) / x)


def _on(world: World) -> np.ndarray:
    owner, placed = owners(world, SPEC)
    (k,) = [k for k, p in enumerate(placed) if p.target is not None]
    return owner == k


def test_the_floor_shows_between_the_legs_in_colour_and_depth() -> None:
    world = _one(LIGHT)
    on, colour, depth = _on(world), render(world, SPEC), render_depth(world, SPEC)
    v = _row(world, 0.25)  # knee height
    cols = np.nonzero(on[v])[0]
    assert cols.size > 0
    gap = [u for u in range(cols.min(), cols.max()) if not on[v, u]]
    assert len(gap) >= 3  # the floor between the two legs
    for u in gap:
        assert (colour[v, u] == background(SPEC)[v, u]).all()
        assert depth[v, u] == floor_depth(SPEC)[v, u]
    # The colour image draws the person exactly where the depth image reads them.
    drawn = np.any(colour != background(SPEC), axis=2)
    np.testing.assert_array_equal(drawn, on)
    empty = floor_depth(SPEC)
    same = (depth == empty) | (np.isnan(depth) & np.isnan(empty))
    np.testing.assert_array_equal(~same, on)


def test_the_torso_is_round_its_sides_farther_than_its_middle_by_half_its_depth() -> None:
    world = _one(LIGHT)
    on, depth = _on(world), render_depth(world, SPEC)
    v = _row(world, 1.2)  # the chest
    middle = depth[v, int(CX)]
    assert middle == pytest.approx(3.0 - LIGHT.depth_m / 2, abs=0.01)
    cols = np.nonzero(on[v])[0]
    # just inside the silhouette's edges (the arms hang beside the chest: take the farthest)
    sides = max(depth[v, cols.min() + 1], depth[v, cols.max() - 1])
    chest = depth[v, cols.min() : cols.max() + 1]
    assert float(np.max(chest)) - middle == pytest.approx(LIGHT.depth_m / 2, abs=0.04)
    assert sides > middle + 0.05
    # it grows steadily from the middle out along the chest
    half = (cols.max() - cols.min()) // 4
    assert depth[v, int(CX) + half] > middle and depth[v, int(CX) - half] > middle


def test_side_on_a_person_is_narrower_and_a_stride_opens_a_gap_between_the_legs() -> None:
    front, side = _one(LIGHT), _one(replace(LIGHT, facing_deg=90.0))
    v = _row(front, 1.2)
    width_front, width_side = _on(front)[v].sum(), _on(side)[v].sum()
    assert width_side < 0.75 * width_front
    # Standing side-on, one leg hides the other; walking across the view, the legs open.
    knee = _row(front, 0.15)
    standing = np.nonzero(_on(side)[knee])[0]
    assert standing.max() - standing.min() + 1 == standing.size  # one run of pixels
    walker = replace(LIGHT, facing_deg=None)
    gaps = []
    for t in np.arange(0.0, 2.0, 0.1):
        w = _one(walker, 3.0, (0.0, 3.0, -1.0), (10.0, 3.0, 1.0))
        w.t = float(t)
        cols = np.nonzero(_on(w)[knee])[0]
        gaps.append(cols.max() - cols.min() + 1 - cols.size)
    assert max(gaps) >= 10  # the floor between the swinging legs
    assert min(gaps) < max(gaps)  # and they swing


def test_the_truth_point_lies_on_the_body_s_front_surface() -> None:
    side = replace(LIGHT, facing_deg=90.0)
    for body in (LIGHT, side, body_for("zoe")):
        world = World(Robot(), targets=[person("p", (0.0, 3.5, 0.4), body=body)])
        ((tid, name, x, y, z),) = targets_in_camera(world, SPEC)
        assert (tid, name) == ("p", "person")
        u, v = int(CX + F * x / z), int(CY + F * y / z)
        assert render_depth(world, SPEC)[v, u] == pytest.approx(z, abs=0.01)
        # on the ray through the axis at half the person's height
        assert y / z == pytest.approx((SPEC.height_m - body.height_m / 2) / 3.5, rel=1e-6)
        # the front of the body, nearer than the centre: by half its depth facing the camera,
        # side-on by half its width or more (the arm hanging at its side)
        nearer = 3.5 - np.hypot(x, z) * 3.5 / np.hypot(0.4, 3.5)
        if body is side:
            assert body.depth_m / 2 < nearer < body.shoulder_m / 2 + 0.1
        else:
            assert nearer == pytest.approx(body.depth_m / 2, abs=0.01)


def test_visibility_counts_the_silhouette_s_pixels() -> None:
    world = _one(LIGHT, 4.0)
    (p,) = [p for p in owners(world, SPEC)[1] if p.target is not None]
    x0, y0, x1, y1 = p.full
    shown = _on(world).sum()
    assert shown < 0.8 * (x1 - x0) * (y1 - y0)  # the rectangle is not the person
    assert targets_in_camera(world, SPEC, min_visible=0.9)  # all of the silhouette shows
    # A tall thin pole in front hides the middle of the person: the share still seen is the
    # silhouette's own.
    hidden = World(Robot(), obstacles=[Obstacle(2.0, 0.0, 0.06, height_m=2.0)],
                   targets=world.targets)  # fmt: skip
    left = _on(hidden).sum() / shown
    assert 0.3 < left < 0.9
    assert targets_in_camera(hidden, SPEC, min_visible=left - 0.05)
    assert not targets_in_camera(hidden, SPEC, min_visible=left + 0.05)


def test_people_differ_and_each_id_keeps_its_look() -> None:
    crowd = people(40, seed=1)
    assert crowd == people(40, seed=1)
    assert body_for("alice") == body_for("alice") != body_for("bob")
    heights = [b.height_m for b in crowd]
    assert min(heights) >= 1.5 and max(heights) <= 1.95 and max(heights) - min(heights) > 0.3
    assert len({b.shoulder_m for b in crowd}) > 30
    dark = [b for b in crowd if b.dark_parts(30)]
    assert 0 < len(dark) < len(crowd)  # some wear clothes a stereo camera loses
    # Every scenario's person has a body of their own; their height is their target's.
    for scenario in SCENARIOS.values():
        for tg in scenario.build().targets:
            assert tg.body is not None and tg.body == body_for(tg.id)
            assert tg.height_m == tg.body.height_m


def test_flat_world_takes_every_body_away_and_leaves_the_world_as_it_was() -> None:
    world = SCENARIOS["two_people"].build()
    flat = flat_world(world)
    assert all(tg.body is None for tg in flat.targets)
    assert all(tg.body is not None for tg in world.targets)
    assert [tg.path for tg in flat.targets] == [tg.path for tg in world.targets]
    flat.advance(0.5)
    assert world.t == 0.0 and flat.robot is not world.robot
    with pytest.raises(ValueError, match="height"):
        Target("x", "person", "person", 1.7, ((0.0, 1.0, 0.0),), body=Body(height_m=1.8))


#: The old simulator's output (before bodies) for :func:`_fixed_world`: the sha256 of the
#: colour then the depth image's bytes, per camera; and what targets_in_camera said.
OLD = {
    (640, 0.0): "1c931ae96c15c72f57c38a9f522c8ad080a897d58b435b92198d99cd49fb6c14",
    (320, 10.0): "a26b0bcaa99f1f0468d466b4fe330786a82cc2c3ccbbd56dc8ade32df569fc3c",
}
OLD_TRUTH_640 = [
    ("a", "person", 0.0755609279643405, -0.2335999580132761, 3.5609658530505466),
    ("b", "person", 0.6459162633338904, -0.2220806758625577, 1.9885928718160448),
    ("c", "person", -0.6907635462730676, -0.1929139070197813, 0.8448375819248539),
]


def _fixed_world() -> World:
    return World(
        Robot(x=0.2, y=-0.1, theta=0.1),
        obstacles=[
            Obstacle(2.0, 0.3, 0.3),
            Obstacle(3.5, -1.0, 0.2, height_m=1.0, material=Material.GLASS),
            Obstacle(2.6, 0.9, 0.25, material=Material.DARK),
        ],
        drops=[Drop(6.0, -3.0, 9.0, 3.0, 0.15)],
        targets=[
            person("a", (0.0, 4.0, 0.2)),
            person("b", (0.0, 2.5, -0.6), mirror=True),
            person("c", (0.0, 1.2, 0.9)),
        ],
    )


def test_a_flat_card_renders_exactly_as_before_bodies() -> None:
    world = flat_world(_fixed_world())
    assert world.targets[0] == card("a", (0.0, 4.0, 0.2))
    for (width, yaw), digest in OLD.items():
        spec = CameraSpec(width=width, height=width * 3 // 4, mount_yaw_deg=yaw)
        h = hashlib.sha256()
        h.update(render(world, spec).tobytes())
        h.update(render_depth(world, spec).tobytes())
        assert h.hexdigest() == digest
    assert targets_in_camera(world, SPEC) == OLD_TRUTH_640
    # ... and the same world with bodies is another picture.
    assert not np.array_equal(render(_fixed_world(), SPEC), render(world, SPEC))
