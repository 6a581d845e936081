"""A worker's capacity as announced (services/detector/capacity.py): measured, smoothed,
announced again only past the step and the period; a user's fixed one never moves."""

from __future__ import annotations

from dataclasses import replace

import pytest

from common.clock import FakeClock
from services.detector.capacity import MIN_CAPACITY_HZ, Capacity, measure
from services.detector.contract import DetectorSettings

S = DetectorSettings(capacity_step=0.25, capacity_period_s=10.0, capacity_smoothing=0.5)


def test_measure_is_frames_over_the_clocks_seconds() -> None:
    clock = FakeClock()

    def one_round() -> int:
        clock.advance(0.1)  # a round of 2 frames takes 0.1 s
        return 2

    assert measure(one_round, 3, clock) == pytest.approx(20.0)


def test_a_moved_capacity_is_announced_past_the_step_and_the_period_only() -> None:
    cap = Capacity(10.0, S, now_s=0.0)
    cap.observe(1, 1 / 11.0)  # 11 frames/s: half-way is 10.5, under the step
    assert cap.current == pytest.approx(10.5)
    assert cap.due(100.0) is None
    for _ in range(10):
        cap.observe(4, 0.1)  # 40 frames/s
    assert cap.current > 12.5
    assert cap.due(5.0) is None  # within the period of the first announcement
    assert cap.due(10.0) is None  # past the step for 5 s only (since 5.0)
    got = cap.due(15.0)
    assert got == cap.announced == pytest.approx(cap.current)
    assert cap.due(30.0) is None  # announced: no move since


def test_a_swing_that_comes_back_within_the_period_is_never_announced() -> None:
    # Issue 39: on a busy CPU the measure swings 22.8 -> 45 -> 59 -> back. Announced only
    # once it has stayed past the step for a whole period, each time.
    cap = Capacity(22.8, replace(S, capacity_smoothing=1.0), now_s=0.0)
    t = 0.0
    for hz in (45.0, 59.0, 24.0, 45.0, 23.0, 59.0, 22.0):  # 4 s each: never 10 s on end
        cap.observe(round(hz * 10), 10.0)
        for _ in range(4):
            t += 1.0
            assert cap.due(t) is None, (hz, t)
    assert cap.announced == 22.8
    cap.observe(450, 10.0)  # 45 Hz, and it stays
    announced = [got for t in range(int(t) + 1, int(t) + 12) if (got := cap.due(float(t)))]
    assert announced == [pytest.approx(45.0)]


def test_a_fixed_capacity_is_the_users_and_never_moves() -> None:
    cap = Capacity(3.0, replace(S, capacity_hz=50.0), now_s=0.0)
    assert cap.fixed and cap.announced == 50.0
    cap.observe(100, 0.1)
    assert cap.current == 50.0 and cap.due(1000.0) is None


def test_an_idle_round_or_a_zero_measure_does_not_sink_it_to_zero() -> None:
    cap = Capacity(0.0, S, now_s=0.0)
    assert cap.announced == MIN_CAPACITY_HZ  # a WorkerAnnouncement's capacity must be > 0
    cap.observe(0, 0.5)
    cap.observe(3, 0.0)
    assert cap.current == MIN_CAPACITY_HZ
