"""The simulated robot under the secure profile: its scenario clock waits for its cameras'
detections (sim.wait_for's "detector"), which its principal must be allowed to hear, or its
world stands still for good while the stack looks up (issue 39)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from common.messages import GroundTruth
from tests.integration.conftest import STARTUP_S, Stack, credentials_for, wait_for

pytestmark = pytest.mark.integration

MOVED_M = 0.2  # the simulated robot has driven once its pose is this far from the start


def test_a_secure_simulated_robot_starts_its_world_and_moves(make_stack, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    creds = tmp_path / "credentials"
    prefix = credentials_for(creds)
    stack: Stack = make_stack(
        zenoh={"mode": "client", "auth": "password", "credentials_dir": str(creds)},
        stack={"prefix": prefix},
        supervisor={"services": ["sim", "detector", "controller"]},
        sim={"scenario": "ahead", "width": 320, "height": 240},
        controller={"mode": "follow", "no_laser": False},
    )
    stack.wait_ready({"sim", "detector", "controller"})
    _, truths = stack.subscribe(stack.keys.sim_truth())

    def moved() -> bool:
        poses = [GroundTruth.decode(t) for t in list(truths)]
        if not poses:
            return False
        (x0, y0, _), (x, y, _) = poses[0].robot, poses[-1].robot
        return poses[-1].sim_time_s > 0 and math.hypot(x - x0, y - y0) >= MOVED_M

    wait_for(moved, STARTUP_S + 60, lambda: f"the simulated robot to move:\n{stack.log()}")
    assert stack.stop() == 0, stack.log()
