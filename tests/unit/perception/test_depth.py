"""perception.depth.measure on synthetic depth images: a flat target before a far background,
with holes, noise, occluders and awkward boxes. Each scene is checked to fool a naive mean of
the box's depths, so a test passes only for a method robust to what it shows."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from common.messages import DepthFrame, Header
from perception.depth import (
    COLUMNS,
    DepthParams,
    Intrinsics,
    depth_metres,
    measure,
    unknown,
)

W, H = 640, 480
INTR = Intrinsics.from_hfov(W, H, 60.0)
F = INTR.fx


def scene(
    target_z: float,
    rect: tuple[int, int, int, int] = (270, 140, 370, 340),
    background_z: float = 8.0,
) -> npt.NDArray[np.float32]:
    """A flat target (rect x0, y0, x1, y1, end-exclusive) at ``target_z`` before a wall."""
    d = np.full((H, W), background_z, np.float32)
    x0, y0, x1, y1 = rect
    d[y0:y1, x0:x1] = target_z
    return d


def box(*xyxy: float) -> npt.NDArray[np.float32]:
    return np.array([xyxy], np.float32)


def naive_mean(depth: npt.NDArray[np.float32], b: npt.NDArray[np.float32]) -> float:
    x0, y0, x1, y1 = (int(v) for v in b[0])
    return float(np.nanmean(depth[y0:y1, x0:x1]))


def row(cols: dict[str, npt.NDArray[np.float32]], i: int = 0) -> dict[str, float]:
    return {k: float(v[i]) for k, v in cols.items()}


def stereo_noise(d: npt.NDArray[np.float32], k: float, seed: int) -> npt.NDArray[np.float32]:
    """A stereo camera's noise: sigma = k * z^2."""
    rng = np.random.default_rng(seed)
    return (d + rng.standard_normal(d.shape).astype(np.float32) * k * d * d).astype(np.float32)


def test_flat_target_before_far_background_box_wider_than_target() -> None:
    d = scene(2.0)
    b = box(230, 120, 410, 360)  # the target fills under half of it
    assert naive_mean(d, b) > 4.0  # the background drags a mean far off
    r = row(measure(d, INTR, b))
    assert r["z_m"] == pytest.approx(2.0, abs=0.005)
    # the centre is the target's: columns 270..370, rows 140..340 back-projected at 2 m
    assert r["x_m"] == pytest.approx((320 - INTR.cx) * 2.0 / F, abs=0.02)
    assert r["y_m"] == pytest.approx((240 - INTR.cy) * 2.0 / F, abs=0.02)
    assert r["distance_m"] == pytest.approx(math.sqrt(r["x_m"] ** 2 + r["y_m"] ** 2 + 4.0))
    # the extent is the target's, not the box's
    assert r["size_x_m"] == pytest.approx(100 * 2.0 / F, rel=0.05)
    assert r["size_y_m"] == pytest.approx(200 * 2.0 / F, rel=0.05)
    assert r["size_z_m"] == pytest.approx(0.0, abs=0.01)


def test_holes_inside_the_target() -> None:
    d = scene(3.0)
    rng = np.random.default_rng(1)
    d[rng.random(d.shape) < 0.4] = np.nan  # 40 % of the pixels read nothing
    d[200:260, 300:340] = np.nan  # and a dark patch in the middle reads nothing at all
    b = box(250, 130, 390, 350)
    assert abs(naive_mean(d, b) - 3.0) > 0.5
    r = row(measure(d, INTR, b))
    assert r["z_m"] == pytest.approx(3.0, abs=0.01)


def test_box_mostly_background() -> None:
    """A thin target (a pole, a person side-on) fills a fifth of its box: the nearest cluster
    with enough of the centre-weighted mass is the object, not the heaviest by count."""
    d = scene(1.5, rect=(305, 100, 335, 400), background_z=5.0)
    b = box(245, 90, 395, 410)  # 30 of 150 columns are the target
    assert naive_mean(d, b) > 4.0
    # the plain median and the plain mode are the background's too
    x0, y0, x1, y1 = (int(v) for v in b[0])
    assert float(np.median(d[y0:y1, x0:x1])) == pytest.approx(5.0)
    r = row(measure(d, INTR, b))
    assert r["z_m"] == pytest.approx(1.5, abs=0.01)
    assert r["size_x_m"] == pytest.approx(30 * 1.5 / F, rel=0.1)


def test_flying_pixels_between_target_and_background() -> None:
    """Real depth cameras read values between two surfaces at their boundary ("flying
    pixels"): a thin bridge of readings from the target to the wall must not join them into
    one cluster, whose median would then be the wall's."""
    rng = np.random.default_rng(6)
    d = scene(1.5, rect=(305, 100, 335, 400), background_z=3.0)
    for cols in (slice(302, 305), slice(335, 338)):
        d[100:400, cols] = rng.uniform(1.5, 3.0, (300, 3)).astype(np.float32)
    d = stereo_noise(d, 0.005, seed=7)
    b = box(245, 90, 395, 410)
    assert naive_mean(d, b) > 2.5
    r = row(measure(d, INTR, b))
    assert r["z_m"] == pytest.approx(1.5, abs=0.02)


def test_a_small_nearer_occluder_is_not_the_object() -> None:
    """Something nearer covering a little of the box (a hand, a chair back) is passed over:
    the object is the nearest cluster with enough weight, not the nearest reading."""
    d = scene(4.0)
    d[230:250, 310:330] = 1.0  # 400 pixels of 20,000 of the target
    b = box(270, 140, 370, 340)
    r = row(measure(d, INTR, b))
    assert r["z_m"] == pytest.approx(4.0, abs=0.02)


def test_noise_growing_with_distance() -> None:
    """A stereo camera's noise (sigma 0.005 z^2: 12 cm at 5 m) with holes and a far floor
    behind: the distance within 2 % at 5 m."""
    truth = scene(5.0, rect=(300, 180, 340, 300), background_z=9.0)
    d = stereo_noise(truth, 0.005, seed=2)
    d[np.random.default_rng(3).random(d.shape) < 0.1] = np.nan
    b = box(290, 170, 350, 310)
    r = row(measure(d, INTR, b))
    assert r["z_m"] == pytest.approx(5.0, rel=0.02)
    # the noise's share is taken out of the depth extent: a flat target stays thin
    assert r["size_z_m"] < 0.25


@pytest.mark.parametrize("z", [0.5, 1.0, 2.0, 4.0, 7.0, 9.5])
def test_noisy_target_at_each_range(z: float) -> None:
    truth = scene(z, background_z=10.0 if z < 9 else 0.4)  # a far wall, or a near one
    d = stereo_noise(truth, 0.005, seed=int(z * 10))
    r = row(measure(d, INTR, box(255, 125, 385, 355)))
    assert r["z_m"] == pytest.approx(z, rel=0.02)


def test_a_target_with_depth_extent() -> None:
    """A ramp from 2.0 m to 2.5 m across the target: z is its middle, size_z its depth."""
    d = scene(2.0)
    d[140:340, 270:370] = np.linspace(2.0, 2.5, 100, dtype=np.float32)[None, :]
    r = row(measure(d, INTR, box(250, 120, 390, 360)))
    assert r["z_m"] == pytest.approx(2.25, abs=0.03)
    assert r["size_z_m"] == pytest.approx(0.5, abs=0.05)


def test_zero_size_and_outside_boxes_are_unknown() -> None:
    d = scene(2.0)
    boxes = np.array(
        [
            [300, 200, 300, 260],  # zero width
            [300, 200, 340, 200],  # zero height
            [340, 200, 300, 260],  # reversed
            [700, 100, 760, 200],  # wholly right of the image
            [-90, -80, -10, -5],  # wholly above and left
            [np.nan, 0, 10, 10],
        ],
        np.float32,
    )
    cols = measure(d, INTR, boxes)
    for name in COLUMNS:
        assert np.isnan(cols[name]).all(), name


def test_edge_clipped_box() -> None:
    """A target cut by the image's left edge, its box running off the image: measured on
    the part inside."""
    d = scene(2.0, rect=(0, 140, 60, 340))
    r = row(measure(d, INTR, box(-40, 130, 70, 350)))
    assert r["z_m"] == pytest.approx(2.0, abs=0.005)
    assert r["x_m"] == pytest.approx((30 - INTR.cx) * 2.0 / F, abs=0.03)


def test_all_invalid_and_too_few_pixels_are_unknown() -> None:
    d = scene(2.0)
    d[100:400, 200:440] = np.nan
    cols = measure(d, INTR, box(250, 150, 390, 350))
    assert all(np.isnan(cols[name][0]) for name in COLUMNS)
    # a handful of readings in an otherwise empty box is not enough to say anything
    d[240:243, 300:303] = 2.0  # 9 valid pixels < min_valid_pixels
    cols = measure(d, INTR, box(250, 150, 390, 350))
    assert all(np.isnan(cols[name][0]) for name in COLUMNS)
    # and fewer than min_valid_fraction of the box is not either
    d[150:160, 250:390] = 2.0  # 5 % of the box: enough by default, not for 10 %
    params = DepthParams(min_valid_fraction=0.1)
    assert np.isnan(measure(d, INTR, box(250, 150, 390, 350), params)["z_m"][0])
    assert measure(d, INTR, box(250, 150, 390, 350))["z_m"][0] == pytest.approx(2.0)


def test_rows_are_independent_and_empty_input() -> None:
    d = scene(2.0)
    d[100:200, 50:150] = 3.0
    boxes = np.array([[270, 140, 370, 340], [0, 0, 0, 0], [50, 100, 150, 200]], np.float32)
    cols = measure(d, INTR, boxes)
    assert cols["z_m"][0] == pytest.approx(2.0)
    assert np.isnan(cols["z_m"][1])
    assert cols["z_m"][2] == pytest.approx(3.0)
    assert all(v.dtype == np.float32 and v.shape == (3,) for v in cols.values())
    empty = measure(d, INTR, np.zeros((0, 4), np.float32))
    assert set(empty) == set(COLUMNS) and all(len(v) == 0 for v in empty.values())
    assert set(unknown(2)) == set(COLUMNS)


def test_large_box_is_sampled_and_still_right() -> None:
    d = stereo_noise(scene(1.0, rect=(100, 50, 540, 430)), 0.005, seed=4)
    r = row(measure(d, INTR, box(80, 30, 560, 450)))  # 200,000 pixels, sampled to 4,096
    assert r["z_m"] == pytest.approx(1.0, abs=0.01)
    assert r["size_x_m"] == pytest.approx(440 / F, rel=0.05)


def test_depth_metres_reads_16uc1_with_holes_and_range() -> None:
    mm = np.array([[0, 250, 1000], [2000, 11000, 65535]], "<u2")
    frame = DepthFrame(
        header=Header(stamp_ns=1, seq=0, frame_id="cam", source="test"),
        encoding="16UC1",
        width=3,
        height=2,
        data=mm.tobytes(),
        fx=1.0,
        fy=1.0,
        cx=1.0,
        cy=1.0,
        range_min_m=0.3,
        range_max_m=10.0,
    )
    z = depth_metres(frame)
    assert z.dtype == np.float32
    assert np.isnan(z[0, 0]) and np.isnan(z[0, 1]) and np.isnan(z[1, 1]) and np.isnan(z[1, 2])
    assert z[0, 2] == pytest.approx(1.0) and z[1, 0] == pytest.approx(2.0)


def test_depth_metres_32fc1_denormals_and_absurd_ranges_are_no_readings() -> None:
    """A 32FC1 source with no stated range: a reading under a millimetre (a denormal) or beyond
    any sensor (3e38) is no reading, never a distance of 0 or infinity."""
    metres = np.array([[1e-30, 0.0005, 1.5], [3e38, -2.0, np.inf]], "<f4")
    frame = DepthFrame(
        header=Header(stamp_ns=1, seq=0, frame_id="cam", source="test"),
        encoding="32FC1",
        width=3,
        height=2,
        data=metres.tobytes(),
        fx=1.0,
        fy=1.0,
        cx=1.0,
        cy=1.0,
    )
    z = depth_metres(frame)
    assert z[0, 2] == pytest.approx(1.5)
    assert np.isnan(np.delete(z.ravel(), 2)).all()
