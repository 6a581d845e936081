"""Freshness verdicts: stale, future, replayed, on the wall and the monotonic clock."""

from __future__ import annotations

from common.clock import Stamp
from common.freshness import FreshnessGate, Verdict, capture_age_s, judge_age
from common.messages import Header

S = 10**9
BOOT = "boot-a"
NOW = Stamp(wall_ns=1000 * S, mono_ns=50 * S)


def hdr(wall_s: float, mono_s: float = 0.0, boot: str = BOOT, source: str = "cam") -> Header:
    return Header(
        stamp_ns=int(wall_s * S),
        frame_id="",
        seq=0,
        source=source,
        mono_ns=int(mono_s * S),
        boot_id=boot if mono_s else "",
    )


def test_age_on_the_wall_clock_alone_for_another_host() -> None:
    assert judge_age(hdr(999.5), NOW, BOOT, 1.0, 0.1) == (Verdict.FRESH, 0.5)
    assert judge_age(hdr(998.0), NOW, BOOT, 1.0, 0.1)[0] is Verdict.STALE
    assert judge_age(hdr(1000.05), NOW, BOOT, 1.0, 0.1) == (Verdict.FRESH, 0.0)
    assert judge_age(hdr(1000.5), NOW, BOOT, 1.0, 0.1)[0] is Verdict.FUTURE
    assert judge_age(hdr(1000 + 3600), NOW, BOOT, 1.0, 0.1)[0] is Verdict.FUTURE
    assert judge_age(hdr(1000 - 3600), NOW, BOOT, 1.0, 0.1)[0] is Verdict.STALE
    assert judge_age(hdr(0), NOW, BOOT, 1.0, 0.1)[0] is Verdict.STALE  # 1970


def test_same_boot_takes_the_worse_of_both_clocks() -> None:
    # The wall clock says 0.2 s, the monotonic one 3 s: the wall clock stepped; stale.
    assert capture_age_s(hdr(999.8, mono_s=47.0), NOW, BOOT) == 3.0
    assert judge_age(hdr(999.8, mono_s=47.0), NOW, BOOT, 1.0, 0.1)[0] is Verdict.STALE
    # Monotonic from the future (a forged stamp) is caught even with a plausible wall stamp.
    assert judge_age(hdr(999.8, mono_s=60.0), NOW, BOOT, 1.0, 0.1)[0] is Verdict.FUTURE
    # Another boot's monotonic stamp means nothing here: the wall clock alone decides.
    assert capture_age_s(hdr(999.8, mono_s=47.0, boot="boot-b"), NOW, BOOT) == 0.2


def test_gate_refuses_a_replay_and_an_older_message_from_the_same_source() -> None:
    gate = FreshnessGate(max_age_s=1.0, future_tolerance_s=0.1, boot_id=BOOT)
    first, second = hdr(999.5, mono_s=49.5), hdr(999.7, mono_s=49.7)
    assert gate.check(first, NOW)[0] is Verdict.FRESH
    assert gate.check(second, NOW)[0] is Verdict.FRESH
    assert gate.check(second, NOW)[0] is Verdict.REPLAY  # the same one again
    assert gate.check(first, NOW)[0] is Verdict.REPLAY  # an older one
    # Another source has its own order.
    assert gate.check(hdr(999.6, mono_s=49.6, source="other"), NOW)[0] is Verdict.FRESH


def test_gate_does_not_remember_rejected_messages() -> None:
    gate = FreshnessGate(max_age_s=1.0, future_tolerance_s=0.1, boot_id=BOOT)
    assert gate.check(hdr(1000 + 3600), NOW)[0] is Verdict.FUTURE
    # Had the future message been remembered, every real one would now look like a replay.
    assert gate.check(hdr(999.9), NOW)[0] is Verdict.FRESH
