"""The depth benchmark's pure parts: range bands, error summaries, the matching of detections to
targets, the naive methods it measures ours against, its worlds and truths, and the
yolo_ros-like reference (each must behave as described, failures included, or the comparison
means nothing)."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest

from common.cli import options_from
from perception.depth import Intrinsics, measure
from services.sim.contract import SimSettings
from simworld.body import body_for
from simworld.depth import DepthNoise, owners
from simworld.render import CameraSpec
from simworld.scenarios import card, person
from simworld.world import Robot, World
from tools.benchmarks.__main__ import _depth_arguments
from tools.benchmarks.depth import (
    BANDS,
    EXTRA,
    METHODS,
    DepthBenchOptions,
    Errors,
    band_of,
    score_depth,
)
from tools.benchmarks.depth_methods import (
    MATCH_IOU,
    centre_pixel,
    horizontal,
    match,
    no_rejection,
    surface,
)
from tools.benchmarks.depth_reference import measure_reference
from tools.benchmarks.depth_synthetic import synthetic_cases
from tools.benchmarks.depth_worlds import Camera, Truth, make_world, truths

INTR = Intrinsics.from_hfov(640, 480, 60.0)
SPEC = CameraSpec(640, 480, 60.0, 0.6)


def test_bands_cover_up_to_the_maximum() -> None:
    assert band_of(0.4) is None
    assert band_of(0.5) == 0
    assert band_of(4.99) == 3
    assert band_of(BANDS[-1][1]) == len(BANDS) - 1
    assert band_of(10.01) is None


def test_the_five_methods_side_by_side() -> None:
    assert METHODS == ("depth", "yolo_ros", "centre", "no_reject", "laser")


# -- the hard world is the default ------------------------------------------------------------
def test_the_hard_world_is_the_default_on_the_command_line_and_in_the_options() -> None:
    p = argparse.ArgumentParser()
    _depth_arguments(p)
    args = p.parse_args([])
    assert options_from(DepthBenchOptions, args, as_json=False).world == "hard"
    assert DepthBenchOptions().world == "hard"
    assert p.parse_args(["--world", "simple"]).world == "simple"


def test_the_hard_camera_runs_the_simulator_s_faults_and_the_simple_one_today_s() -> None:
    """The hard world's depth camera is the simulator's default (bias, flying pixels), its
    colour camera has its faults, and people keep their bodies; the simple world's is
    ``DepthNoise()``, no colour faults, people as flat cards."""
    hard, simple = Camera("hard", 1), Camera("simple", 1)
    s = SimSettings()
    assert hard.noise.bias_k == s.depth_bias_k > 0
    assert hard.noise.flying_share == s.depth_flying_share > 0
    assert hard.colour_faults.on
    assert simple.noise == DepthNoise()
    assert not simple.colour_faults.on
    rng, look = np.random.default_rng(3), np.random.default_rng(4)
    built = make_world(rng, look, (2.0, 3.0), 60.0)
    assert all(tg.body is not None for tg in built.targets)
    assert all(tg.body is not None for tg in hard.frame(built).world.targets)
    assert all(tg.body is None for tg in simple.frame(built).world.targets)


def test_both_worlds_place_people_alike() -> None:
    """The same seeds give the same places in both worlds (the simple world's table is the
    same worlds' with flat people), and a person's look does not move anyone."""
    a = make_world(np.random.default_rng(9), np.random.default_rng(1), (3.0, 5.0), 60.0)
    b = make_world(np.random.default_rng(9), np.random.default_rng(2), (3.0, 5.0), 60.0)
    pa = [tg.position(a.t) for tg in a.targets]
    assert np.allclose(pa, [tg.position(b.t) for tg in b.targets])
    # each the same person (by key), posed by the look's stream
    assert [tg.height_m for tg in a.targets] == [tg.height_m for tg in b.targets]


# -- truths -----------------------------------------------------------------------------------
def test_a_card_s_truths_are_its_front_face_its_rectangle_and_the_laser_s_circle() -> None:
    """A flat-card person 3 m ahead (0.25 m radius) and one 4 m ahead off to the left: the
    depth methods are held to the face the camera sees, the laser to its circle's nearest
    point, the box height to its axis; its true box is its drawn rectangle."""
    world = World(Robot(), targets=[card("a", (0.0, 3.0, 0.0)), card("b", (0.0, 4.0, 1.0))])
    got = truths(world, SPEC)
    a = got["a"]
    assert a.point[2] == pytest.approx(2.75)
    assert a.face_h == pytest.approx(2.75)  # straight ahead: the horizontal range is z
    assert a.surface == pytest.approx(2.75)
    assert a.centre == pytest.approx(math.hypot(3.0, 0.6 - 1.7 / 2))
    _, placed = owners(world, SPEC)
    k = next(i for i, p in enumerate(placed) if p.target == 0)
    assert a.box == placed[k].rect
    b = got["b"]
    drop = (0.6 - 1.7 / 2) * b.point[2] / 4.0
    assert b.face_h > b.point[2]
    assert b.face_h == pytest.approx(math.sqrt(b.face**2 - drop**2), rel=1e-4)
    assert b.surface == pytest.approx(math.hypot(4.0, 1.0) - 0.25)


def test_a_body_s_true_box_is_its_silhouette_s_not_its_rectangle() -> None:
    """A person with a body: the true visible box bounds the pixels they own (their
    silhouette, fewer than its box's), inside the rectangle drawn for them; the depth
    truth is their surface."""
    world = World(Robot(), targets=[person("a", (0.0, 2.0, 0.0), body=body_for("a"))])
    t = truths(world, SPEC)["a"]
    owner, placed = owners(world, SPEC)
    (k,) = (i for i, p in enumerate(placed) if p.target == 0)
    x0, y0, x1, y1 = placed[k].rect or (0, 0, 0, 0)
    bx0, by0, bx1, by1 = t.box
    assert x0 <= bx0 and bx1 <= x1 and y0 <= by0 and by1 <= y1
    ys, xs = np.nonzero(owner == k)
    assert len(xs) < 0.8 * (bx1 - bx0) * (by1 - by0)
    assert t.box == (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1)
    assert 1.6 < t.point[2] < 2.0  # the front of the body, nearer than its axis


# -- matching by IoU --------------------------------------------------------------------------
def test_detections_match_targets_by_iou_best_first_one_to_one() -> None:
    targets = np.array([[100, 50, 200, 400], [180, 60, 280, 400], [500, 100, 540, 200]])
    dets = np.array(
        [
            [185, 60, 282, 398],  # the second target's, overlapping the first
            [98, 48, 205, 402],  # the first's
            [300, 0, 320, 20],  # nobody's
            [100, 50, 200, 225],  # the first's upper half: the first is taken already
        ],
        np.float32,
    )
    assert match(dets, targets, MATCH_IOU) == {1: 0, 0: 1}
    assert match(dets, targets, 0.99) == {}
    assert match(dets[:0], targets, MATCH_IOU) == {}


def test_a_box_whose_centre_shows_the_floor_still_matches_its_person() -> None:
    """The centre pixel of a walking person's box can fall between their legs (the owner
    there is nobody); the IoU with their true box still pairs them."""
    targets = np.array([[300, 100, 360, 400]])
    owner = np.full((480, 640), -1)
    owner[100:400, 300:360] = 0
    owner[240:400, 325:335] = -1  # the floor between the legs, under the box's centre
    det = np.array([[301, 102, 359, 398]], np.float32)
    u, v = int(det[0, [0, 2]].mean()), int(det[0, [1, 3]].mean())
    assert owner[v, u] == -1
    assert match(det, targets, MATCH_IOU) == {0: 0}


# -- the naive methods ------------------------------------------------------------------------
def _scene(z: float, rect: tuple[int, int, int, int], back: float) -> np.ndarray:
    d = np.full((480, 640), back, np.float32)
    x0, y0, x1, y1 = rect
    d[y0:y1, x0:x1] = z
    return d


def test_the_centre_pixel_reads_the_box_s_centre_and_nothing_else() -> None:
    d = _scene(2.0, (300, 100, 340, 400), 6.0)
    box = np.array([[200, 100, 440, 400]], np.float32)  # centre (320, 250): on the target
    got = centre_pixel(d, INTR, box)
    assert got["z_m"][0] == pytest.approx(2.0)
    assert got["x_m"][0] == pytest.approx((320.5 - 320) * 2.0 / INTR.fx)
    assert horizontal(got, 0) == pytest.approx(math.hypot(got["x_m"][0], 2.0))
    d[250, 320] = np.nan  # a hole there: unknown, whatever the rest of the box reads
    assert math.isnan(centre_pixel(d, INTR, box)["z_m"][0])
    off = np.array([[100, 100, 300, 400]], np.float32)  # centre on the background
    assert centre_pixel(d, INTR, off)["z_m"][0] == pytest.approx(6.0)


def test_no_rejection_takes_the_background_in_where_ours_rejects_it() -> None:
    """A thin target filling 20 % of its box before a wall: ours finds the target; the
    weighted median of every reading in the box is dragged to the wall."""
    d = _scene(1.5, (305, 100, 335, 400), 5.0)
    box = np.array([[245, 90, 395, 410]], np.float32)
    assert measure(d, INTR, box)["z_m"][0] == pytest.approx(1.5)
    assert no_rejection(d, INTR, box)["z_m"][0] > 4.0
    # A target filling its box: both read it.
    full = np.array([[305, 100, 335, 400]], np.float32)
    assert no_rejection(d, INTR, full)["z_m"][0] == pytest.approx(1.5)
    # Too few readings: unknown, as ours.
    sparse = np.full((480, 640), np.nan, np.float32)
    sparse[240:242, 300:305] = 2.0
    wide = np.array([[250, 150, 390, 350]], np.float32)
    assert math.isnan(no_rejection(sparse, INTR, wide)["z_m"][0])


def test_the_surface_oracle_reads_only_the_target_s_own_true_pixels() -> None:
    d = _scene(2.0, (305, 100, 335, 400), 5.0)
    owner = np.full(d.shape, -1, np.int32)
    owner[100:400, 305:335] = 3
    box = np.array([245, 90, 395, 410], np.float32)  # 80 % background
    x, z = surface(d, owner, 3, INTR, box)
    assert z == pytest.approx(2.0)
    assert x == pytest.approx((320 - INTR.cx) * 2.0 / INTR.fx, abs=0.01)
    assert math.isnan(surface(d, owner, 4, INTR, box)[1])  # nobody's: unknown


def test_scoring_is_by_horizontal_range_for_every_depth_method() -> None:
    x, y, z = 0.3, -0.4, 0.8
    t = Truth((0, 0, 1, 1), (x, y, z), math.hypot(x, z), math.sqrt(x * x + y * y + z * z), 1.0, 1.0)
    errors = {m: [Errors()] for m in METHODS + EXTRA}

    def row(dx: float, dy: float) -> dict[str, np.ndarray]:
        a, b = x + dx, y + dy
        d = math.sqrt(a * a + b * b + z * z)
        return {
            k: np.array([v], np.float32)
            for k, v in zip(("x_m", "y_m", "z_m", "distance_m"), (a, b, z, d), strict=True)
        }

    measured = {"depth": row(0, 0.3), "yolo_ros": row(0.02, 0), "centre": row(0, 0)}
    measured["no_reject"] = {k: np.full(1, np.nan, np.float32) for k in measured["depth"]}
    score_depth(errors, 0, measured, 0, t)
    # a vertical offset moves the 3D distance, not the horizontal range
    assert errors["depth"][0].summary()["median_m"] == pytest.approx(0.0, abs=1e-6)
    assert errors["depth_3d"][0].summary()["median_m"] > 0.05
    expected = math.hypot(x + 0.02, z) - math.hypot(x, z)
    assert errors["yolo_ros"][0].summary()["median_m"] == pytest.approx(expected, abs=1e-6)
    assert errors["no_reject"][0].summary() == {"n": 0, "unknown": 1, "unknown_pct": 100.0}


def test_errors_count_unknowns_apart() -> None:
    e = Errors()
    e.add(2.1, 2.0)
    e.add(1.8, 2.0)
    e.add(math.nan, 2.0)
    e.add(0.0, 2.0)  # the laser's "nothing valid"
    s = e.summary()
    assert s["n"] == 2 and s["unknown"] == 2 and s["unknown_pct"] == pytest.approx(50.0)
    assert s["median_m"] == pytest.approx(0.15)
    assert s["median_pct"] == pytest.approx(7.5)
    assert s["median_all_pct"] is None  # half the rows unknown: the median is a miss
    e.add(2.0, 2.0)
    assert e.summary()["median_all_pct"] == pytest.approx(10.0)  # 0, 5, 10, inf, inf


# -- the yolo_ros-like reference and the synthetic cases --------------------------------------
def test_reference_finds_a_target_filling_its_box() -> None:
    d = _scene(3.0, (270, 140, 370, 340), 8.0)
    rng = np.random.default_rng(0)
    d += (rng.standard_normal(d.shape) * 0.005 * d * d).astype(np.float32)
    r = measure_reference(d, INTR, np.array([[260, 130, 380, 350]], np.float32))
    assert r["z_m"][0] == pytest.approx(3.0, abs=0.03)
    assert r["distance_m"][0] == pytest.approx(
        math.sqrt(r["x_m"][0] ** 2 + r["y_m"][0] ** 2 + r["z_m"][0] ** 2), rel=1e-5
    )


def test_hard_cases_where_the_methods_differ() -> None:
    """The background-dominated box fools the mode (yolo_ros) and the plain median, not the
    nearest heavy cluster (ours); a box of 10 readings gets a number from yolo_ros and none
    from ours."""
    cases = {c["case"]: c for c in synthetic_cases()}
    thin = cases["thin target, box 80 % background"]
    assert thin["depth"] == pytest.approx(1.5, abs=0.02)
    assert thin["yolo_ros"] > 4.0
    assert thin["no_reject"] > 4.0
    sparse = cases["10 valid pixels in the box"]
    assert math.isnan(sparse["depth"]) and sparse["yolo_ros"] == pytest.approx(2.0)
