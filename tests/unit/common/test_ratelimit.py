"""The log limiter: the first lines per key in full, then one summary per period, by reason."""

from __future__ import annotations

import pytest

from common.ratelimit import LogLimiter


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_first_lines_then_one_summary_per_period_with_counts_by_reason() -> None:
    clock = FakeClock()
    lim = LogLimiter(burst=3, period_s=10.0, clock=clock)
    verdicts = [lim.admit("stack/camera/front/frame", "bad_input") for _ in range(1000)]
    assert [v.log for v in verdicts[:4]] == [True, True, True, False]
    assert not any(v.log or v.summary for v in verdicts[3:])  # no time passed: silence
    clock.t += 10.0
    v = lim.admit("stack/camera/front/frame", "frames_oversize")
    assert not v.log
    assert v.summary == (
        "stack/camera/front/frame: 997 more not logged in the last 10 s (bad_input 997)"
    )
    clock.t += 5.0
    assert not lim.admit("stack/camera/front/frame", "bad_input").summary  # within the period
    clock.t += 5.0
    v = lim.admit("stack/camera/front/frame", "bad_input")
    assert v.summary.endswith("2 more not logged in the last 10 s (frames_oversize 1, bad_input 1)")


def test_keys_are_limited_apart_and_a_quiet_key_starts_afresh() -> None:
    clock = FakeClock()
    lim = LogLimiter(burst=1, period_s=10.0, clock=clock)
    assert lim.admit("a", "x").log
    assert not lim.admit("a", "x").log
    assert lim.admit("b", "x").log  # another key has its own budget
    assert lim.drain() == ["a: 1 more not logged in the last 0 s (x 1)"]
    assert not lim.drain()  # reported once
    lim.admit("a", "y")
    assert not lim.due()  # its period is not over
    clock.t += 10.0
    assert lim.due() == ["a: 1 more not logged in the last 10 s (y 1)"]
    clock.t += 11.0  # a whole period without an event on "a"
    assert lim.admit("a", "x").log


def test_keys_and_reasons_are_bounded() -> None:
    lim = LogLimiter(burst=0, period_s=10.0, clock=FakeClock(), max_keys=4)
    for i in range(100):
        lim.admit(f"k{i}", "x")
    assert len(lim.drain()) == 4  # only the newest keys are remembered
    for i in range(50):
        lim.admit("k99", f"reason{i}")
    (line,) = [s for s in lim.drain() if s.startswith("k99")]
    assert "other 42" in line and line.count(",") == 8


def test_bad_parameters_are_refused() -> None:
    with pytest.raises(ValueError):
        LogLimiter(period_s=0)
