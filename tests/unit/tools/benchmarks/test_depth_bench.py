"""The depth benchmark's pure parts: range bands, error summaries, and the yolo_ros-like
reference it measures ours against (it must behave as described, failures included, or the
comparison means nothing)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from perception.depth import Intrinsics
from services.sim.render import CameraSpec
from services.sim.scenarios import person
from services.sim.world import Robot, World
from tools.benchmarks.depth import BANDS, Errors, band_of, synthetic_cases, truths
from tools.benchmarks.depth_reference import measure_reference

INTR = Intrinsics.from_hfov(640, 480, 60.0)


def test_bands_cover_up_to_the_maximum() -> None:
    assert band_of(0.4) is None
    assert band_of(0.5) == 0
    assert band_of(4.99) == 3
    assert band_of(BANDS[-1][1]) == len(BANDS) - 1
    assert band_of(10.01) is None


def test_the_depth_truth_is_the_visible_front_face_and_the_box_s_the_centre() -> None:
    """A person 3 m ahead (0.25 m radius) and one 4 m ahead off to the left: the depth methods
    are scored against the face the camera sees, the box height against the drawn centre."""
    world = World(Robot(), targets=[person("a", (0.0, 3.0, 0.0)), person("b", (0.0, 4.0, 1.0))])
    spec = CameraSpec(640, 480, 60.0, 0.6)
    got = truths(world, spec, min_visible=0.3)
    a = got["a"]
    centre = math.hypot(3.0, 0.6 - 1.7 / 2)  # half its height, 0.25 m below the lens
    assert a.centre == pytest.approx(centre)
    assert a.face_z == pytest.approx(2.75)
    assert a.face == pytest.approx(centre * 2.75 / 3.0)
    b = got["b"]
    assert b.face_z == pytest.approx(3.75)
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
