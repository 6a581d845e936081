"""Attention's state (services/detector/attention.py) on a FakeClock: what has priority, for
how long, and the order a round is arranged in."""

from __future__ import annotations

import pytest

from common.clock import FakeClock
from services.detector.attention import FLOOR, PRIORITY, SPARE, Attention


def _attention(clock: FakeClock, enabled: bool = True) -> Attention:
    return Attention(clock, floor_hz=1.0, hold_s=2.0, enabled=enabled)


def test_the_locked_camera_has_priority_for_hold_s_after_the_last_status() -> None:
    clock = FakeClock()
    att = _attention(clock)
    att.taken(["rear"])
    assert att.priority() == frozenset()
    att.controller("rear", ("person",))
    assert att.priority() == {"rear"}
    clock.advance(2.0)
    assert att.priority() == {"rear"}
    clock.advance(0.01)
    assert att.priority() == frozenset()  # the controller went quiet: the lock is not believed
    att.controller("rear", ("person",))
    att.controller("", ("person",))  # the controller lost its target
    assert att.priority() == frozenset()


def test_a_camera_that_saw_a_target_class_has_priority_for_hold_s() -> None:
    clock = FakeClock()
    att = _attention(clock)
    att.taken(["left", "front"])
    att.saw("left", ["person", "dog"])
    assert att.priority() == frozenset()  # no target classes heard yet
    att.controller("", ("person",))
    assert att.priority() == {"left"}
    att.saw("rear", ["dog"])  # not a target class
    clock.advance(1.5)
    att.saw("front", ["person"])
    assert att.priority() == {"left", "front"}
    clock.advance(0.6)
    assert att.priority() == {"front"}
    clock.advance(1.5)
    assert att.priority() == frozenset()


def test_without_priorities_the_order_is_left_as_it_is() -> None:
    clock = FakeClock()
    att = _attention(clock)
    att.taken(["a"])
    clock.advance(5.0)
    assert att.arrange(["c", "a", "b"]) == [("c", ""), ("a", ""), ("b", "")]
    off = _attention(clock, enabled=False)
    off.controller("b", ("person",))
    assert off.priority() == frozenset()
    assert off.arrange(["c", "a", "b"]) == [("c", ""), ("a", ""), ("b", "")]


def test_priority_first_then_spare_and_a_camera_due_for_its_floor_goes_ahead() -> None:
    clock = FakeClock()
    att = _attention(clock)
    att.taken(["a", "b", "c"])
    att.controller("c", ("person",))
    clock.advance(0.5)
    assert att.arrange(["a", "b", "c"]) == [("c", PRIORITY), ("a", SPARE), ("b", SPARE)]
    att.taken(["c"])
    clock.advance(0.5)  # a and b have not been taken for 1 s = 1 / floor: due
    assert att.arrange(["b", "a", "c"]) == [("b", FLOOR), ("a", FLOOR), ("c", PRIORITY)]
    att.taken(["b"])
    clock.advance(0.2)
    att.controller("c", ("person",))
    assert att.arrange(["b", "a", "c"]) == [("a", FLOOR), ("c", PRIORITY), ("b", SPARE)]


def test_the_camera_due_longest_goes_first_and_a_never_taken_one_is_due() -> None:
    clock = FakeClock()
    att = _attention(clock)
    att.controller("p", ("person",))
    att.taken(["x"])
    clock.advance(0.3)
    att.taken(["y", "p"])
    clock.advance(1.5)
    # All due: the one never taken first, then by how long each has been due; a priority
    # camera that is due keeps its reason.
    assert att.arrange(["y", "p", "x", "new"]) == [
        ("new", FLOOR),
        ("x", FLOOR),
        ("y", FLOOR),
        ("p", PRIORITY),
    ]


def test_a_lock_on_a_camera_this_worker_never_had_leaves_its_rounds_fair() -> None:
    """In a pool the controller's camera may be another worker's."""
    clock = FakeClock()
    att = _attention(clock)
    att.taken(["a", "b"])
    clock.advance(5.0)  # both due, were anything prioritised
    att.controller("elsewhere", ("person",))
    assert att.priority() == frozenset()
    assert att.arrange(["b", "a"]) == [("b", ""), ("a", "")]
    # Once that camera is this worker's (its frame waits here), it has priority (and, never
    # taken, is due first).
    assert att.arrange(["b", "a", "elsewhere"]) == [
        ("elsewhere", PRIORITY),
        ("b", FLOOR),
        ("a", FLOOR),
    ]


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="floor_hz"):
        Attention(FakeClock(), floor_hz=0.0, hold_s=1.0)
    with pytest.raises(ValueError, match="hold_s"):
        Attention(FakeClock(), floor_hz=1.0, hold_s=-1.0)
