"""The scripted detector kill (tools/scenarios/runner.py): from its time on, once the robot
moves, so that the scenario shows a stop from motion also on a loaded machine, where the
robot may stand for a stale detection at that very moment (issue 39, a CI run)."""

from __future__ import annotations

import numpy as np

from common.messages import GroundTruth, Header, Twist
from tools.scenarios.runner import KILL_WAIT_MOVING_S, _kill_now
from tools.scenarios.score import ScenarioLog

HDR = Header(stamp_ns=1, frame_id="world", source="sim", seq=0)
KILL_AT = 6.0


def at(t: float, linear_x: float) -> ScenarioLog:
    truth = GroundTruth(
        header=HDR, sim_time_s=t, robot=(0.0, 0.0, 0.0), targets_xy=np.zeros((0, 2))
    )
    return ScenarioLog(truths=[truth], twists=[Twist(header=HDR, linear=(linear_x, 0.0, 0.0))])


def test_the_kill_waits_for_motion_but_not_for_ever() -> None:
    assert not _kill_now(at(KILL_AT - 0.1, 0.5), KILL_AT)  # not yet
    assert _kill_now(at(KILL_AT, 0.5), KILL_AT)  # moving at its time
    assert not _kill_now(at(KILL_AT + 1.0, 0.0), KILL_AT)  # stopped: wait for motion
    assert _kill_now(at(KILL_AT + KILL_WAIT_MOVING_S, 0.0), KILL_AT)  # but not for ever
