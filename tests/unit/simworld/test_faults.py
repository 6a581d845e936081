"""The harder world's camera faults (simworld/faults.py, and their place in simworld/depth.py's
``apply``): flying pixels, range bias, mirrors, motion blur and exposure; and that with them
off the depth camera is today's, bit for bit."""

from __future__ import annotations

import dataclasses
import hashlib
import math

import numpy as np
import pytest

from simworld.depth import DepthNoise, apply, render_depth
from simworld.faults import (
    ColourFaults,
    Exposure,
    blur_px,
    colour_faults,
    edge_faults,
    mirror_reads,
    motion_blur,
)
from simworld.render import MIRROR_BGR, OBSTACLE_BGR, CameraSpec, render
from simworld.world import Material, Obstacle, Robot, Target, World

#: Every older fault off: what is left is the one under test, and mm quantisation.
QUIET = DepthNoise(noise_k=0.0, edge_px=0, dark_dropout=0.0, dropout=0.0)
BRIGHT = np.full((120, 160, 3), 200, np.uint8)


def card(id: str, x: float, y: float) -> Target:
    """Today's person: the flat photo cut-out, 1.7 m tall, standing at (x, y)."""
    return Target(id=id, name="person", sprite="person", height_m=1.7, path=((0.0, x, y),))


def _box_on_plane(near: float = 2.0, far: float = 4.0) -> np.ndarray:
    """A plane at ``far`` with a box at ``near`` in its middle, every pixel read (160x120)."""
    truth = np.full((120, 160), far, np.float32)
    truth[40:80, 60:100] = near
    return truth


def test_flying_pixels_lie_strictly_between_the_near_and_the_far_surface() -> None:
    truth = _box_on_plane()
    noise = dataclasses.replace(QUIET, edge_px=2, flying_share=1.0)
    got = apply(truth, BRIGHT, noise, np.random.default_rng(0))
    changed = got != truth
    assert np.isfinite(got).all()  # share 1: no hole between two surfaces
    assert 400 < changed.sum() < 1000  # a band round the box's 4 edges, about 2+2 px wide
    inside = got[changed]
    assert (inside >= 2.0).all() and (inside <= 4.0).all()
    assert ((inside > 2.0) & (inside < 4.0)).mean() > 0.95  # mm rounding may touch an end
    # Only near the edge: nothing changes 4 px or more away from it.
    far_from_edge = np.ones_like(changed)
    far_from_edge[36:84, 56:104] = False
    far_from_edge[44:76, 64:96] = True
    assert not changed[far_from_edge].any()


def test_half_the_edge_band_flies_and_the_rest_is_holes_and_beside_no_reading_only_holes() -> None:
    truth = _box_on_plane()
    truth[:10] = np.nan  # a stripe of no reading (the wall at infinity)
    hole, flying, values = edge_faults(truth, 2, 0.1, 0.5, np.random.default_rng(1))
    band = hole[20:] | flying[20:]
    assert flying.sum() / band.sum() == pytest.approx(0.5, abs=0.06)
    assert not (hole & flying).any()
    assert np.isfinite(values[flying]).all() and np.isnan(values[~flying]).all()
    # Beside the stripe of no reading, holes as before, no flying pixel.
    assert hole[10:12].all() and not flying[:14].any()
    # Share 0 through apply is today's: the band is holes.
    old = apply(truth, BRIGHT, dataclasses.replace(QUIET, edge_px=2), np.random.default_rng(0))
    assert np.isnan(old[38:42, 70]).all()


def test_range_bias_grows_with_the_square_of_the_range_at_the_stated_rate() -> None:
    bias_k = 0.0025
    noise = dataclasses.replace(QUIET, bias_k=bias_k)
    for z in (1.0, 2.0, 5.0, 8.0):
        truth = np.full((120, 160), z, np.float32)
        got = apply(truth, BRIGHT, noise, np.random.default_rng(0))
        # k z^2 metres, to the mm: 0.5 % of the range at 2 m, 2 % at 8 m.
        assert np.all(np.abs(got - (z + bias_k * z * z)) <= 0.0005 + 1e-6)
    assert got.mean() / 8.0 - 1.0 == pytest.approx(0.02, abs=1e-4)


def test_the_hard_camera_s_noise_at_2_m_is_its_setting_and_within_the_d435_datasheet() -> None:
    """sigma = noise_k z^2: 2 cm (1 %) at 2 m; with the bias (0.5 %) the RMS error is still
    under the D435's 2 % at 2 m."""
    noise = DepthNoise(noise_k=0.005, bias_k=0.0025, edge_px=0, dark_dropout=0.0, dropout=0.0)
    truth = np.full((240, 320), 2.0, np.float32)
    rng = np.random.default_rng(3)
    errors = np.stack([apply(truth, BRIGHT, noise, rng) - 2.0 for _ in range(8)])
    bias = 0.0025 * 4.0
    assert errors.mean() == pytest.approx(bias, abs=0.003)
    assert (errors - bias).std() == pytest.approx(0.005 * 4.0, rel=0.1)
    assert np.sqrt(np.mean(errors**2)) / 2.0 < 0.02


def test_in_disparity_the_bias_and_noise_are_the_range_space_ones_to_first_order() -> None:
    """1 / (1 / z - bias_k + noise_k n): at 2 m the same bias (1 cm) and sigma (2 cm) as in
    range space, the bias a hair more (its second order: z^3 k^2)."""
    noise = DepthNoise(
        noise_k=0.005, bias_k=0.0025, edge_px=0, dark_dropout=0.0, dropout=0.0, in_disparity=True
    )
    truth = np.full((240, 320), 2.0, np.float32)
    rng = np.random.default_rng(3)
    errors = np.stack([apply(truth, BRIGHT, noise, rng) - 2.0 for _ in range(8)])
    assert errors.mean() == pytest.approx(0.0025 * 4.0, abs=0.003)
    assert errors.std() == pytest.approx(0.005 * 4.0, rel=0.1)
    quiet = dataclasses.replace(QUIET, bias_k=0.0025, in_disparity=True)
    for z in (1.0, 2.0, 5.0):
        got = apply(np.full((8, 8), z, np.float32), BRIGHT[:8, :8], quiet, rng)
        assert np.all(np.abs(got - 1.0 / (1.0 / z - 0.0025)) <= 0.0005 + 1e-6)


@pytest.mark.parametrize("in_disparity", [False, True])
def test_a_floor_far_away_never_reads_near_in_disparity_space(in_disparity: bool) -> None:
    """The hard camera looking at an empty floor: its rows just under the horizon are tens of
    metres away, and flying pixels keep readings there. Noise in range space (sigma = k z^2,
    18 m at 60 m) makes some of them read a metre or two: a phantom obstacle at the robot's
    feet (a depth-only follower stood blocked by one). In disparity space none reads under
    half its truth; range space is the control that the test can see it."""
    spec = CameraSpec(width=320, height=240, hfov_deg=87.0, height_m=0.3)
    world = World(robot=Robot(0.0, 0.0, 0.0))
    truth = render_depth(world, spec)
    noise = DepthNoise(bias_k=0.0025, flying_share=0.5, in_disparity=in_disparity)
    rng = np.random.default_rng(0)
    near = 0
    for _ in range(100):
        got = apply(truth, render(world, spec), noise, rng)
        near += int(np.sum(np.isfinite(got) & (got < truth / 2)))
    if in_disparity:
        assert near == 0
    else:
        assert near > 0


def test_a_mirror_reads_farther_than_its_face_and_is_drawn_bright_steel() -> None:
    spec = CameraSpec(width=160, height=120)
    mirror = Obstacle(2.0, 0.0, 0.3, material=Material.MIRROR)
    world = World(Robot(), obstacles=[mirror])
    truth = render_depth(world, spec)
    solid = render_depth(World(Robot(), obstacles=[Obstacle(2.0, 0.0, 0.3)]), spec)
    np.testing.assert_array_equal(truth, solid)  # the geometry is a solid box's
    face = solid == np.float32(1.7)
    assert face.sum() > 100
    read = mirror_reads(world, spec, truth, 2.0)
    np.testing.assert_allclose(read[face], 3.4, rtol=1e-6)
    np.testing.assert_array_equal(read[~face], truth[~face])
    assert mirror_reads(world, spec, truth, 1.0) is truth
    # A person in front of the mirror keeps their own depth (0.95 m: 1.2 m less 0.25 m).
    world.targets.append(card("p", 1.2, 0.5))
    before = render_depth(world, spec)
    after = mirror_reads(world, spec, before, 2.0)
    them = before == np.float32(0.95)
    assert (them & face).any() and (face & ~them).any()  # they hide part of it
    np.testing.assert_array_equal(after[them], before[them])
    np.testing.assert_allclose(after[face & ~them], 3.4, rtol=1e-6)
    # Its colour: bright steel, not the grey solid box.
    colour = render(World(Robot(), obstacles=[mirror]), spec)
    assert tuple(colour[face][0]) == MIRROR_BGR != OBSTACLE_BGR


def test_motion_blur_is_yaw_rate_times_exposure_times_focal_length_pixels() -> None:
    image = np.zeros((60, 200, 3), np.uint8)
    image[:, 100:] = 255  # one sharp vertical edge
    focal = 400.0
    for w, expected in ((0.5, 4), (1.5, 12)):
        assert blur_px(w, 0.02, focal) == pytest.approx(expected)
        got = motion_blur(image, -w, 0.02, focal)  # either way round
        ramp = np.count_nonzero((got[30, :, 0] > 0) & (got[30, :, 0] < 255))
        assert ramp == expected - 1  # a box of n pixels leaves n - 1 mixed ones
    assert motion_blur(image, 0.05, 0.02, focal) is image  # under 2 px: no blur


def test_exposure_jumps_when_turning_to_the_light_and_comes_back_with_its_time_constant() -> None:
    faults = ColourFaults(light_change=0.3, light_tau_s=1.0)
    exposure = Exposure(faults, light_bearing=0.0)
    rng = np.random.default_rng(0)
    side = math.pi / 2  # side-lit: scene 0
    assert exposure.gain(0.0, side, rng) == pytest.approx(1.0)
    assert exposure.gain(5.0, side, rng) == pytest.approx(1.0)
    # A sudden turn to face the light: e^0.3 brighter at once, then 1/e of it left after tau.
    assert exposure.gain(5.0, 0.0, rng) == pytest.approx(math.exp(0.3))
    assert exposure.gain(6.0, 0.0, rng) == pytest.approx(math.exp(0.3 / math.e))
    assert exposure.gain(20.0, 0.0, rng) == pytest.approx(1.0, abs=1e-5)
    # Away from the light: darker, by the same rule.
    assert exposure.gain(20.0, math.pi, rng) == pytest.approx(math.exp(-0.6))
    image = np.full((10, 10, 3), 100, np.uint8)
    darker = colour_faults(image, exposure, 20.0, math.pi, 0.0, 500.0, rng)
    assert darker[0, 0, 0] == round(100 * math.exp(-0.6))


def test_the_gain_drifts_slowly_with_its_sigma_and_repeats_with_the_seed() -> None:
    faults = ColourFaults(drift=0.05, drift_tau_s=10.0)

    def run(seed: int) -> np.ndarray:
        exposure, rng = Exposure(faults, 0.0), np.random.default_rng(seed)
        return np.log([exposure.gain(0.2 * k, 0.0, rng) for k in range(20000)])

    logs = run(1)
    assert logs.std() == pytest.approx(0.05, rel=0.2)
    assert abs(logs[1] - logs[0]) < 0.02  # slow: a frame's step is small
    np.testing.assert_array_equal(logs, run(1))
    assert not np.array_equal(logs, run(2))


def test_with_the_newer_faults_off_the_depth_camera_is_today_s_bit_for_bit() -> None:
    """The digest of today's output (main at a821d63, before these faults), for a fixed seed:
    uncorrelated noise, so that no float blur's last bit decides a millimetre."""
    spec = CameraSpec(width=96, height=72)
    world = World(
        Robot(),
        targets=[card("p", 3.0, 0.3), card("q", 6.0, -1.5)],
        obstacles=[Obstacle(2.0, -0.6, 0.2), Obstacle(2.5, 0.9, 0.2, material=Material.DARK)],
    )
    truth, image = render_depth(world, spec), render(world, spec)
    rng, digest = np.random.default_rng(7), hashlib.sha256()
    for _ in range(3):
        z = apply(truth, image, DepthNoise(noise_corr_px=0.0), rng)
        digest.update(np.nan_to_num(np.round(z * 1000), nan=0).astype("<i4").tobytes())
    assert digest.hexdigest() == "2d95f11053f083fe8a17278302e538de67ad27219452570e4fc0813278845066"
