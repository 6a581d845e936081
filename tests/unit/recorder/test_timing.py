"""A replay's schedule and stamps: original spacing over the rate, stamps never ahead."""

from __future__ import annotations

import pytest

from common.clock import Stamp
from common.freshness import FreshnessGate, Verdict
from common.messages import Header
from services.recorder.timing import MAX_LAG_NS, Schedule

S = 1_000_000_000


def test_messages_are_due_at_their_recorded_spacing_over_the_rate() -> None:
    sched = Schedule(2.0, Stamp(100 * S, 5 * S), first_log_ns=40 * S)
    assert sched.due(40 * S) == Stamp(100 * S, 5 * S)
    assert sched.due(42 * S) == Stamp(101 * S, 6 * S)
    with pytest.raises(ValueError, match="positive"):
        Schedule(0.0, Stamp(0, 0), 0)


def test_restamping_keeps_a_small_lag_and_drops_a_foreign_clock() -> None:
    sched = Schedule(1.0, Stamp(100 * S, 5 * S), first_log_ns=40 * S)
    lag = 3_000_000
    assert sched.restamp(41 * S, 41 * S - lag) == Stamp(101 * S - lag, 6 * S - lag)
    # A bag stamped on simulated time (or in the future) is stamped when it was recorded.
    assert sched.restamp(41 * S, 7 * S) == sched.due(41 * S)
    assert sched.restamp(41 * S, 41 * S + MAX_LAG_NS) == sched.due(41 * S)


def test_the_freshness_gate_takes_a_replay_as_live_and_each_frame_as_new() -> None:
    sched = Schedule(1.0, Stamp(100 * S, 5 * S), first_log_ns=0)
    gate = FreshnessGate(max_age_s=1.0, future_tolerance_s=0.1, boot_id="b")
    for log_ns in (0, S // 5, 2 * S // 5):
        at = sched.restamp(log_ns, log_ns - 2_000_000)
        header = Header(stamp_ns=at.wall_ns, frame_id="", seq=1, source="replay",
                        mono_ns=at.mono_ns, boot_id="b")  # fmt: skip
        now = sched.due(log_ns)  # published when due
        assert gate.check(header, Stamp(now.wall_ns + 1_000_000, now.mono_ns + 1_000_000))[0] is (
            Verdict.FRESH
        )


def test_one_capture_stamp_is_one_new_stamp_whenever_it_was_recorded() -> None:
    # A depth image and its colour frame: captured together, recorded a few ms apart. The
    # replay stamps them alike, so that the detector pairs them as it did live.
    sched = Schedule(3.0, Stamp(100 * S, 5 * S), first_log_ns=40 * S)
    stamp = 41 * S + 7
    stamps = {sched.restamp(stamp + lag, stamp) for lag in (1_000_001, 2_000_000, 4_999_999)}
    assert len(stamps) == 1
