"""The camera's skipped-frame log: the first few one by one, then a summary per period."""

from __future__ import annotations

import logging

import pytest

from services.camera.skips import SkipLog


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_first_skips_are_logged_then_summarised_per_period(
    caplog: pytest.LogCaptureFixture,
) -> None:
    clock = FakeClock()
    skips = SkipLog(logging.getLogger("camera.test"), first_logged=2, period_s=10.0, clock=clock)
    with caplog.at_level(logging.WARNING, logger="camera.test"):
        for i in range(50):  # 50 skips within one period: 2 lines, no summary yet
            skips.skip(ValueError(f"bad {i}"))
        assert [r.getMessage() for r in caplog.records] == [
            "skipped: bad 0",
            "skipped: bad 1 (further skips are summarised)",
        ]
        clock.t += 10.0
        skips.skip(ValueError("bad 50"))  # the period is over: one summary of the 49 since
        skips.skip(ValueError("bad 51"))
        skips.flush()  # at the end: the one not reported yet
        skips.flush()  # nothing left: no line
    messages = [r.getMessage() for r in caplog.records]
    assert messages[2:] == [
        "skipped 49 more unreadable frame(s) (51 in all); the latest: bad 50",
        "skipped 1 more unreadable frame(s) (52 in all); the latest: bad 51",
    ]
    assert skips.total == 52
