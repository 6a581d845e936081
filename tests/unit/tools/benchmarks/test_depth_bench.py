"""The depth benchmark's pure parts: range bands, error summaries, and the yolo_ros-like
reference it measures ours against (it must behave as described, failures included, or the
comparison means nothing)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from perception.depth import Intrinsics
from simworld.render import CameraSpec
from simworld.scenarios import card
from simworld.world import Robot, World
from tools.benchmarks.depth import (
    BANDS,
    EXTRA,
    METHODS,
    Errors,
    Truth,
    band_of,
    score_depth,
    synthetic_cases,
    truths,
)
from tools.benchmarks.depth_reference import measure_reference

INTR = Intrinsics.from_hfov(640, 480, 60.0)


def test_bands_cover_up_to_the_maximum() -> None:
    assert band_of(0.4) is None
    assert band_of(0.5) == 0
    assert band_of(4.99) == 3
    assert band_of(BANDS[-1][1]) == len(BANDS) - 1
    assert band_of(10.01) is None


def test_the_depth_truth_is_the_visible_front_face_and_the_box_s_the_centre() -> None:
    """A flat-card person 3 m ahead (0.25 m radius) and one 4 m ahead off to the left: the
    depth methods are scored against the face the camera sees, the box height against the
    drawn centre."""
    world = World(Robot(), targets=[card("a", (0.0, 3.0, 0.0)), card("b", (0.0, 4.0, 1.0))])
    spec = CameraSpec(640, 480, 60.0, 0.6)
    got = truths(world, spec, min_visible=0.3)
    a = got["a"]
    centre = math.hypot(3.0, 0.6 - 1.7 / 2)  # half its height, 0.25 m below the lens
    assert a.centre == pytest.approx(centre)
    assert a.face_z == pytest.approx(2.75)
    assert a.face == pytest.approx(centre * 2.75 / 3.0)
    assert a.face_h == pytest.approx(2.75)  # straight ahead: the horizontal range is z
    b = got["b"]
    assert b.face_z == pytest.approx(3.75)
    # off to the left: more than z, less than the 3D distance by the drop to half its height
    drop = (0.6 - 1.7 / 2) * b.face_z / 4.0
    assert b.face_h > b.face_z
    assert b.face_h == pytest.approx(math.sqrt(b.face**2 - drop**2), rel=1e-4)
    assert b.centre - b.face == pytest.approx(0.25, abs=0.01)


def test_errors_count_unknowns_apart() -> None:
    e = Errors()
    e.add(2.1, 2.0)
    e.add(1.8, 2.0)
    e.add(math.nan, 2.0)
    e.add(0.0, 2.0)  # the laser's "nothing valid"
    s = e.summary()
    assert s["n"] == 2 and s["unknown"] == 2
    assert s["median_m"] == pytest.approx(0.15)
    assert s["median_pct"] == pytest.approx(7.5)


def test_reference_finds_a_target_filling_its_box() -> None:
    d = np.full((480, 640), 8.0, np.float32)
    d[140:340, 270:370] = 3.0
    rng = np.random.default_rng(0)
    d += (rng.standard_normal(d.shape) * 0.005 * d * d).astype(np.float32)
    r = measure_reference(d, INTR, np.array([[260, 130, 380, 350]], np.float32))
    assert r["z_m"][0] == pytest.approx(3.0, abs=0.03)
    assert r["distance_m"][0] == pytest.approx(
        math.sqrt(r["x_m"][0] ** 2 + r["y_m"][0] ** 2 + r["z_m"][0] ** 2), rel=1e-5
    )


def test_hard_cases_where_the_methods_differ() -> None:
    """The background-dominated box fools the mode (yolo_ros) but not the nearest heavy
    cluster (ours); a box of 10 readings gets a number from yolo_ros and none from ours."""
    cases = {c["case"]: c for c in synthetic_cases()}
    thin = cases["thin target, box 80 % background"]
    assert thin["depth"] == pytest.approx(1.5, abs=0.02)
    assert thin["yolo_ros"] > 4.0
    sparse = cases["10 valid pixels in the box"]
    assert math.isnan(sparse["depth"]) and sparse["yolo_ros"] == pytest.approx(2.0)


def _row(x: float, y: float, z: float) -> dict[str, np.ndarray]:
    return {
        "x_m": np.array([x], np.float32),
        "y_m": np.array([y], np.float32),
        "z_m": np.array([z], np.float32),
        "distance_m": np.array([math.sqrt(x * x + y * y + z * z)], np.float32),
    }


def test_the_horizontal_range_ignores_a_vertical_offset() -> None:
    """A near person cut by the image's top and bottom: the visible part's centre is 0.3 m
    below the truth's point, x and z exact. The 3D distance is off; the horizontal range
    hypot(x, z), what the controller follows by, is exact for both methods."""
    x, y, z = 0.3, -0.4, 0.8
    truth = Truth(math.sqrt(x * x + y * y + z * z), z, math.hypot(x, z), 1.0)
    errors = {m: [Errors()] for m in METHODS + EXTRA}
    measured = _row(x, y + 0.3, z)
    score_depth(errors, 0, measured, _row(x + 0.02, y + 0.3, z), 0, truth)
    assert errors["depth"][0].summary()["median_m"] > 0.05
    assert errors["depth_z"][0].summary()["median_m"] == pytest.approx(0.0, abs=1e-6)
    ours = errors["depth_h"][0].summary()
    assert ours["n"] == 1 and ours["median_m"] == pytest.approx(0.0, abs=1e-6)
    ref = errors["yolo_ros_h"][0].summary()
    expected = math.hypot(x + 0.02, z) - math.hypot(x, z)
    assert ref["median_m"] == pytest.approx(expected, abs=1e-6)
    assert ref["median_pct"] == pytest.approx(expected / math.hypot(x, z) * 100, rel=1e-4)


def test_an_unknown_horizontal_range_is_counted_unknown() -> None:
    errors = {m: [Errors()] for m in METHODS + EXTRA}
    nan = _row(math.nan, math.nan, math.nan)
    score_depth(errors, 0, nan, nan, 0, Truth(1.0, 1.0, 1.0, 1.2))
    assert errors["depth_h"][0].summary() == {"n": 0, "unknown": 1}
    assert errors["yolo_ros_h"][0].summary() == {"n": 0, "unknown": 1}
