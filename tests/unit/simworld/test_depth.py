"""The simulator's depth camera (simworld/depth.py): the true depth image drawn from the
colour image's geometry, the truth of each target's visible front face, and a stereo camera's
faults."""

from __future__ import annotations

import numpy as np
import pytest

from common.messages import Header
from perception.depth import Intrinsics, depth_metres, measure
from simworld.depth import (
    IDEAL,
    DepthNoise,
    apply,
    depth_frame,
    floor_depth,
    render_depth,
    targets_in_camera,
    unit_noise,
)
from simworld.render import OBSTACLE_HEIGHT_M, CameraSpec, background, render
from simworld.scenarios import card
from simworld.world import Obstacle, Robot, Target, World

SPEC = CameraSpec(width=320, height=240, hfov_deg=60.0, height_m=0.6)
HDR = Header(stamp_ns=123, frame_id="cam", seq=7, source="sim")
BRIGHT = np.full((SPEC.height, SPEC.width, 3), 200, np.uint8)


def _thing(world: World, spec: CameraSpec = SPEC) -> np.ndarray:
    """The pixels where something is drawn over the empty scene, in the colour image."""
    return np.any(render(world, spec) != background(spec), axis=2)


def test_the_floor_reads_its_distance_row_by_row_and_above_the_horizon_nothing() -> None:
    depth = render_depth(World(Robot()), SPEC)
    f, cy = SPEC.focal_px, SPEC.height / 2
    assert np.isnan(depth[: SPEC.height // 2]).all()  # the wall at infinity: no reading
    for v in (121, 130, 180, 239):
        z = f * SPEC.height_m / (v + 0.5 - cy)
        assert depth[v] == pytest.approx(np.full(SPEC.width, z), rel=1e-6)
        # Back-projected, the row's point is on the floor: camera height below the lens.
        assert (v + 0.5 - cy) * depth[v, 0] / f == pytest.approx(SPEC.height_m, rel=1e-6)
    # The bottom row of a 0.6 m high camera with 60 deg hfov (4:3, so 47 deg vfov) sees the
    # floor 0.6 m / tan(23.4 deg) ahead.
    assert depth[-1, 0] == pytest.approx(1.39, abs=0.01)


def test_a_target_reads_its_front_face_over_exactly_the_pixels_it_is_drawn_on() -> None:
    world = World(Robot(), targets=[card("p", (0.0, 3.0, 0.4))])
    depth = render_depth(world, SPEC)
    drawn = _thing(world)
    assert drawn.sum() > 500
    # Its front face (as the laser sees it), not its centre: 3.0 m less its 0.25 m radius.
    assert world.targets[0].radius == 0.25
    assert np.all(depth[drawn] == pytest.approx(2.75))
    # Everywhere else: the empty world's depth.
    np.testing.assert_array_equal(depth[~drawn], floor_depth(SPEC)[~drawn])
    # The billboard stands on the floor and reaches above the horizon (1.7 m > 0.6 m).
    rows = np.nonzero(drawn.any(axis=1))[0]
    assert rows.min() < SPEC.height / 2 < rows.max()


def test_an_obstacle_reads_its_front_face_and_nearer_things_hide_farther_ones() -> None:
    world = World(
        Robot(),
        obstacles=[Obstacle(2.0, 0.0, 0.3)],
        targets=[card("p", (0.0, 4.0, 0.0))],
    )
    depth = render_depth(world, SPEC)
    f, cy = SPEC.focal_px, SPEC.height / 2
    box_top = round(cy + f * (SPEC.height_m - OBSTACLE_HEIGHT_M) / 2.0)
    box_bottom = round(cy + f * SPEC.height_m / 2.0)
    col = SPEC.width // 2
    # The obstacle's box (its front face, as the laser sees it) in front of the person.
    assert depth[box_top + 1 : box_bottom, col] == pytest.approx(1.7)
    # The person above the low box, behind it (their front face).
    assert depth[box_top - 3, col] == pytest.approx(3.75)
    # Swap: the person in front hides the obstacle.
    world = World(
        Robot(),
        obstacles=[Obstacle(4.0, 0.0, 0.3)],
        targets=[card("p", (0.0, 2.0, 0.0))],
    )
    depth = render_depth(world, SPEC)
    assert depth[SPEC.height // 2 :, col][depth[SPEC.height // 2 :, col] < 3.0].size > 0
    assert not np.any(np.isclose(depth, 3.7))  # the obstacle is wholly behind the person


def test_depth_covers_the_pixels_the_colour_image_draws_from_any_camera() -> None:
    rng = np.random.default_rng(3)
    specs = (SPEC, CameraSpec(160, 121, 90.0, 0.3), CameraSpec(320, 240, 60.0, 0.6, 180.0))
    for _ in range(15):
        obstacles = [Obstacle(*rng.uniform([-6, -3, 0.1], [8, 3, 0.6])) for _ in range(3)]
        targets = [
            Target(id=f"t{j}", name="x", sprite=str(rng.choice(["person", "cat", "cup"])),
                   height_m=float(rng.uniform(0.2, 2.0)),
                   path=((0.0, *rng.uniform([-8, -4], [10, 4])),))
            for j in range(3)
        ]  # fmt: skip
        world = World(Robot(theta=float(rng.uniform(-1, 1))), obstacles=obstacles, targets=targets)
        for spec in specs:
            depth, empty = render_depth(world, spec), floor_depth(spec)
            covered = ~((depth == empty) | (np.isnan(depth) & np.isnan(empty)))
            drawn = _thing(world, spec)
            assert not np.any(drawn & ~covered)
            # A photo's pixel may happen to match the background's: rarely.
            assert (covered & ~drawn).sum() <= 0.01 * max(covered.sum(), 1)


def test_targets_in_camera_are_their_front_faces_on_the_centre_ray_in_the_optical_frame() -> None:
    world = World(
        Robot(theta=0.1),
        targets=[
            card("near", (0.0, 3.0, 0.5)),
            Target(id="cup", name="cup", sprite="cup", height_m=0.3, path=((0.0, 5.0, -1.0),)),
            card("gone", (0.0, -2.0, 0.0)),  # behind the camera
        ],
    )
    seen = {t[0]: t for t in targets_in_camera(world, SPEC)}
    assert set(seen) == {"near", "cup"}
    c, s = np.cos(0.1), np.sin(0.1)
    _, name, x, y, z = seen["near"]
    assert name == "person"
    # The centre at half its height: z ahead, right of the axis +x, below the lens +y ...
    centre = np.array([-(-3.0 * s + 0.5 * c), 0.6 - 1.7 / 2, 3.0 * c + 0.5 * s])
    # ... seen at its front face (0.25 m nearer) on the ray through it.
    face = centre * (centre[2] - 0.25) / centre[2]
    assert (x, y, z) == pytest.approx(tuple(face))
    assert np.linalg.norm((x, y, z)) == pytest.approx(np.linalg.norm(centre) - 0.25, abs=0.01)
    # The baseline depth method on a perfect depth image finds that same centre.
    depth = apply(render_depth(world, SPEC), render(world, SPEC), IDEAL, np.random.default_rng(0))
    drawn = np.argwhere(render_depth(world, SPEC) == np.float32(z))
    (y0, x0), (y1, x1) = drawn.min(axis=0), drawn.max(axis=0) + 1
    intr = Intrinsics.from_hfov(SPEC.width, SPEC.height, SPEC.hfov_deg)
    got = measure(depth, intr, np.array([[x0, y0, x1, y1]], np.float32))
    assert (got["x_m"][0], got["y_m"][0], got["z_m"][0]) == pytest.approx((x, y, z), abs=0.02)


def test_a_target_hidden_by_a_nearer_one_is_not_in_camera() -> None:
    cup = Target(id="cup", name="cup", sprite="cup", height_m=0.3, path=((0.0, 5.0, 0.0),))
    world = World(Robot(), targets=[card("p", (0.0, 2.0, 0.0)), cup])
    assert [t[0] for t in targets_in_camera(world, SPEC)] == ["p"]
    # Beside the person it is seen; with most of it to be seen asked, still.
    world = World(Robot(), targets=[card("p", (0.0, 3.0, 1.0)), cup])
    assert [t[0] for t in targets_in_camera(world, SPEC, min_visible=0.9)] == ["cup", "p"]


def _flat(z: float, shape: tuple[int, int] = (200, 200)) -> np.ndarray:
    return np.full(shape, z, np.float32)


def _bright(shape: tuple[int, int]) -> np.ndarray:
    return np.full((*shape, 3), 200, np.uint8)


def test_noise_grows_with_the_square_of_the_distance() -> None:
    noise = DepthNoise(noise_k=0.005, noise_corr_px=0, edge_px=0, dark_dropout=0.0, dropout=0.0)
    rng = np.random.default_rng(1)
    std = {}
    for z in (1.0, 2.0, 4.0):
        got = apply(_flat(z), _bright((200, 200)), noise, rng)
        assert np.isfinite(got).all()
        assert np.mean(got) == pytest.approx(z, abs=0.01)  # unbiased
        std[z] = float(np.std(got - z))
        assert std[z] == pytest.approx(0.005 * z**2, rel=0.1)
    assert std[2.0] / std[1.0] == pytest.approx(4, rel=0.15)
    assert std[4.0] / std[2.0] == pytest.approx(4, rel=0.15)
    assert std[2.0] / 2.0 == pytest.approx(0.01, rel=0.1)  # 1 % at 2 m, as a D435


def _correlation(n: np.ndarray, d: int) -> float:
    """The correlation of pixels ``d`` apart along rows, over a stack of unit noise images."""
    return float(np.mean(n[..., d:] * n[..., :-d]))


def test_correlated_noise_keeps_each_pixel_s_sigma_and_neighbours_share_it() -> None:
    rng = np.random.default_rng(3)
    shape = (120, 160)
    white = np.stack([unit_noise(shape, 0, rng) for _ in range(40)])
    blobs = np.stack([unit_noise(shape, 4.0, rng) for _ in range(40)])
    assert blobs.dtype == np.float32 and blobs.shape == (40, *shape)
    # Each pixel's sigma is still 1, at the image's edges too (the blur's rescaling).
    assert float(np.std(blobs)) == pytest.approx(1.0, abs=0.03)
    assert float(np.std(blobs[:, :, :3])) == pytest.approx(1.0, abs=0.08)
    assert float(np.std(blobs[:, :3, :])) == pytest.approx(1.0, abs=0.08)
    assert float(np.mean(blobs)) == pytest.approx(0.0, abs=0.05)
    # Pixels d apart correlate exp(-d^2 / (4 sigma^2)); independent noise not at all.
    for d in (1, 4, 8):
        assert _correlation(blobs, d) == pytest.approx(np.exp(-(d**2) / 64), abs=0.05)
        assert _correlation(white, d) == pytest.approx(0.0, abs=0.02)
    # So a box's mean keeps far more of the noise: a 40x30 box, 1200 pixels, averages about
    # 1200 / (4 pi sigma^2) = 6 independent errors rather than 1200.
    box_white = float(np.std(white[:, 40:80, 60:90].mean(axis=(1, 2))))
    box_blobs = float(np.std(blobs[:, 40:80, 60:90].mean(axis=(1, 2))))
    assert box_white == pytest.approx(1 / np.sqrt(1200), rel=0.3)
    assert box_blobs > 8 * box_white


def test_correlated_depth_noise_is_k_z_squared_per_pixel_in_blobs() -> None:
    noise = DepthNoise(noise_k=0.005, noise_corr_px=4.0, edge_px=0, dark_dropout=0, dropout=0)
    rng = np.random.default_rng(4)
    got = np.stack([apply(_flat(3.0), _bright((200, 200)), noise, rng) for _ in range(10)])
    err = got - 3.0
    assert float(np.std(err)) == pytest.approx(0.005 * 9, rel=0.05)  # 4.5 cm at 3 m, as before
    assert _correlation(err / (0.005 * 9), 1) > 0.9  # a neighbour shares its error
    medians = np.median(err, axis=(1, 2))  # the whole 200x200 image's median, per frame
    assert float(np.max(np.abs(medians))) > 0.002  # independent noise: within 0.5 mm


def test_readings_outside_the_range_are_holes_and_the_rest_millimetres() -> None:
    truth = np.array([[0.1, 0.29, 0.3, 1.23456, 9.9994, 10.0, 10.2, np.nan]], np.float32)
    got = apply(truth, _bright(truth.shape), IDEAL, np.random.default_rng(0))
    np.testing.assert_allclose(
        got[0], [np.nan, np.nan, 0.3, 1.235, 9.999, 10.0, np.nan, np.nan], atol=1e-6
    )
    narrow = DepthNoise(range_min_m=1.0, range_max_m=5.0, noise_k=0, edge_px=0, dropout=0)
    got = apply(_flat(0.5, (1, 4)), _bright((1, 4)), narrow, np.random.default_rng(0))
    assert np.isnan(got).all()


def test_depth_edges_are_holes_a_few_pixels_wide() -> None:
    truth = _flat(2.0, (50, 60))
    truth[:, 30:] = 4.0  # a step at column 30
    truth[:, 55:] = 4.2  # a slope, not an edge (5 %)
    noise = DepthNoise(noise_k=0.0, edge_px=2, dark_dropout=0.0, dropout=0.0)
    got = apply(truth, _bright(truth.shape), noise, np.random.default_rng(0))
    holes = np.nonzero(np.isnan(got).all(axis=0))[0]
    assert list(holes) == [27, 28, 29, 30, 31, 32]
    assert np.isfinite(np.delete(got, holes, axis=1)).all()
    # Next to a pixel with no reading (the sky, say) too.
    truth[:10] = np.nan
    got = apply(truth, _bright(truth.shape), noise, np.random.default_rng(0))
    assert np.isnan(got[:13]).all() and np.isfinite(got[13:, :20]).all()


def test_dark_surfaces_and_random_pixels_drop_out() -> None:
    colour = _bright((200, 200))
    colour[:, :100] = 10  # dark on the left
    noise = DepthNoise(noise_k=0.0, edge_px=0, dark_level=30, dark_dropout=0.5, dropout=0.0)
    got = apply(_flat(2.0), colour, noise, np.random.default_rng(2))
    assert np.isnan(got[:, :100]).mean() == pytest.approx(0.5, abs=0.02)
    assert np.isfinite(got[:, 100:]).all()
    noise = DepthNoise(noise_k=0.0, edge_px=0, dark_dropout=0.0, dropout=0.05)
    got = apply(_flat(2.0), colour, noise, np.random.default_rng(2))
    assert np.isnan(got).mean() == pytest.approx(0.05, abs=0.01)


def test_depth_frame_is_16uc1_millimetres_with_the_camera_s_intrinsics() -> None:
    depth = np.array([[1.2344, np.nan], [0.0, 70.0]], np.float32)
    spec = CameraSpec(width=2, height=2, hfov_deg=90.0)
    noise = DepthNoise(range_min_m=0.2, range_max_m=8.0)
    frame = depth_frame(depth, spec, HDR, noise)
    assert frame.header == HDR and frame.encoding == "16UC1"
    assert (frame.fx, frame.fy, frame.cx, frame.cy) == pytest.approx((1.0, 1.0, 1.0, 1.0))
    assert (frame.range_min_m, frame.range_max_m) == (0.2, 8.0)
    assert list(np.frombuffer(frame.data, "<u2")) == [1234, 0, 0, 65535]
    back = depth_metres(frame)
    assert back[0, 0] == pytest.approx(1.234) and np.isnan(back[[0, 1, 1], [1, 0, 1]]).all()
