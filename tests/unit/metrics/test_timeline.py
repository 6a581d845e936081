from __future__ import annotations

import pytest

from services.metrics.window import Timeline


def test_gaps_are_zero_and_the_current_period_is_left_out() -> None:
    tl = Timeline(span_s=60.0)
    tl.add(10.2, frames=1)
    tl.add(10.7, frames=1)
    tl.add(13.1, frames=1)
    out = tl.series(13.5, ("frames", "dropped"))
    assert out == {"t": [10.0, 11.0, 12.0], "frames": [2.0, 0.0, 0.0], "dropped": [0.0] * 3}


def test_old_periods_are_forgotten() -> None:
    tl = Timeline(span_s=5.0)
    for t in range(20):
        tl.add(float(t), frames=1)
    assert tl.series(19.5, ("frames",))["t"] == [14.0, 15.0, 16.0, 17.0, 18.0]
    assert tl.totals(19.5, span_s=2.0) == {"frames": 3.0}  # periods 17, 18, 19


def test_spread_shares_an_amount_by_overlap() -> None:
    tl = Timeline(span_s=60.0)
    tl.spread(1.5, 3.5, offered=20)  # 10 per second: 5 in [1.5, 2), 10 in [2, 3), 5 in [3, 3.5)
    assert tl.series(4.0, ("offered",))["offered"] == pytest.approx([5.0, 10.0, 5.0])
    tl.spread(5.0, 5.0, offered=3)  # an empty interval: all of it at that instant
    assert tl.totals(5.5, span_s=0.5) == {"offered": 3.0}


def test_since_drops_the_periods_that_begin_before_it() -> None:
    tl = Timeline(span_s=60.0)
    for t in (0.5, 1.5, 2.5, 3.5):
        tl.add(t, frames=1)
    assert tl.series(4.0, ("frames",), since=1.2)["t"] == [2.0, 3.0]
    assert tl.series(4.0, ("frames",), since=2.0)["t"] == [2.0, 3.0]
