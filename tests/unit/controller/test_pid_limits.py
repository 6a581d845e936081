from __future__ import annotations

import pytest

from services.controller.limits import Limits, limit
from services.controller.pid import PID, PIDGains


def test_proportional_only() -> None:
    assert PID(PIDGains(kp=2.0)).update(0.5, dt=0.1) == pytest.approx(1.0)


def test_output_is_limited() -> None:
    assert PID(PIDGains(kp=10.0, output_limit=0.7)).update(-1.0, 0.1) == pytest.approx(-0.7)


def test_integral_accumulates_and_is_clamped() -> None:
    pid = PID(PIDGains(kp=0.0, ki=1.0, integral_limit=0.3))
    outputs = [pid.update(1.0, dt=0.1) for _ in range(10)]
    assert outputs[0] == pytest.approx(0.1) and outputs[1] == pytest.approx(0.2)
    assert outputs[-1] == pytest.approx(0.3)  # clamped: no wind-up
    pid.reset()
    assert pid.update(0.0, 0.1) == 0.0


def test_derivative_uses_the_previous_error() -> None:
    pid = PID(PIDGains(kp=0.0, kd=1.0))
    assert pid.update(0.0, 0.1) == 0.0  # no history yet
    assert pid.update(0.2, 0.1) == pytest.approx(2.0)


LIM = Limits(max_linear=0.5, max_angular=1.0, max_linear_accel=1.0, max_angular_accel=4.0)


def test_speed_limits() -> None:
    assert limit((0.5, 1.0), (2.0, -3.0), dt=10.0, lim=LIM) == (0.5, -1.0)


def test_acceleration_limits() -> None:
    v, w = limit((0.0, 0.0), (0.5, 1.0), dt=0.1, lim=LIM)
    assert v == pytest.approx(0.1) and w == pytest.approx(0.4)
    v, w = limit((0.5, 0.0), (0.0, 0.0), dt=0.1, lim=LIM)
    assert v == pytest.approx(0.4)  # decelerates too


def test_no_time_no_change() -> None:
    assert limit((0.2, 0.1), (0.5, 1.0), dt=0.0, lim=LIM) == (0.2, 0.1)
