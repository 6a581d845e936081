"""The simulator's pace (services/sim/pacing.py): the world keeps the wall clock's time, so a
starved simulator does not turn its base slower than commanded (issue 41: the controller,
on the wall clock, predicted a turn the slowed world had not made)."""

from __future__ import annotations

import pytest

from services.sim.pacing import Pace

DT = 0.02


def test_a_slow_pass_takes_the_steps_it_owes() -> None:
    pace = Pace(DT, max_steps=10)
    pace.start(0.0)
    assert pace.due(0.02) == 1
    assert pace.due(0.10) == 4  # a pass 80 ms late: four steps, the world at 0.10 s
    assert pace.at == pytest.approx(0.10)
    assert pace.due(0.11) == 0  # early by less than a step: none yet
    assert pace.due(0.12) == 1
    assert pace.given_up_s == 0.0


def test_the_world_keeps_the_wall_clock_over_many_slow_passes() -> None:
    pace = Pace(DT, max_steps=10)
    pace.start(0.0)
    steps = sum(pace.due(0.045 * k) for k in range(1, 201))  # passes of 45 ms
    assert steps * DT == pytest.approx(200 * 0.045, abs=DT)


def test_beyond_the_most_a_pass_takes_the_rest_is_given_up_and_counted() -> None:
    pace = Pace(DT, max_steps=5)
    pace.start(0.0)
    assert pace.due(1.0) == 5  # 0.1 s of physics, never a burst of 50 steps
    assert pace.given_up_s == pytest.approx(0.9)
    assert pace.due(1.02) == 1  # and on from the wall clock's now
