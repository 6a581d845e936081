"""The live depth error of a scenario run (tools/scenarios/depth_truth.py): a person detection's
horizontal range against the point a depth camera observes of the person it looks at, drawn
again from the scenario's world at the truth's moment."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.boxes import Boxes
from common.messages import Detections, GroundTruth, Header
from services.sim.cameras import sim_cameras
from services.sim.contract import SimSettings, SimWorld
from services.sim.worlds import world_for
from simworld.depth import targets_in_camera
from simworld.scenarios import SCENARIOS
from stack.config import Config
from tools.scenarios.depth_truth import BEARING_GATE_DEG, depth_error

HDR = Header(stamp_ns=1_000, frame_id="camera", source="sim", seq=0)


def _truth() -> GroundTruth:
    return GroundTruth(header=HDR, sim_time_s=0.0, robot=(0.0, 0.0, 0.0))


def _dets(columns: list[tuple[float, float, float]], shift_px: float = 0.0) -> Detections:
    """Person boxes centred on the camera's axis (``shift_px`` to the right), with these
    (x, y, z) depth columns."""
    n = len(columns)
    u = 320 + shift_px
    xyz = np.array(columns, np.float32).reshape(n, 3)
    return Detections(
        header=HDR,
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.tile(np.array([[u - 30, 100, u + 30, 400]], np.float32), (n, 1)),
            scores=np.full(n, 0.9, np.float32),
            class_ids=np.zeros(n, np.int32),
            columns={"x_m": xyz[:, 0], "y_m": xyz[:, 1], "z_m": xyz[:, 2]},
        ),
        class_names=("person",),
    )


@pytest.mark.parametrize("world", ["hard", "simple"])
def test_a_range_two_percent_long_reads_two_percent(world: str) -> None:
    config = Config(sim=SimSettings(world=SimWorld(world)))
    scenario = SCENARIOS["ahead"]
    drawn = world_for(config.sim, scenario.build())  # bodies, or the flat cards of "simple"
    ((_, _, x, y, z),) = targets_in_camera(drawn, sim_cameras(config)[0].spec)
    # The flat card's front face 0.25 m before its centre, 4 m ahead; a body's, its hips'.
    assert z == pytest.approx(3.75, abs=0.01) if world == "simple" else 3.76 < z < 3.95
    long = (x * 1.02, y * 1.02, z * 1.02)
    got = depth_error(scenario.build(), config, [_truth()], {"front": [_dets([long])]})
    assert got is not None and got["rows"] == 1 and got["unknown"] == 0
    assert got["median_pct"] == pytest.approx(2.0, abs=0.01)
    assert got["median_signed_m"] == pytest.approx(0.02 * math.hypot(x, z), abs=1e-3)


def test_no_depth_is_unknown_and_a_box_off_every_target_is_left_out() -> None:
    config = Config()
    scenario = SCENARIOS["ahead"]
    nan = (math.nan, math.nan, math.nan)
    unknown = depth_error(scenario.build(), config, [_truth()], {"front": [_dets([nan])]})
    assert unknown is not None and unknown["rows"] == 0 and unknown["unknown"] == 1
    # A box further off the person's bearing than the gate matches nobody.
    off_px = 554 * math.tan(math.radians(BEARING_GATE_DEG * 3))
    away = depth_error(
        scenario.build(), config, [_truth()], {"front": [_dets([(1.0, 0.0, 3.0)], off_px)]}
    )
    assert away is None


def test_nothing_heard_gives_no_figures() -> None:
    assert depth_error(SCENARIOS["ahead"].build(), Config(), [], {"front": []}) is None
