"""Track mode obeys the forward-safety rules of follow mode, on real processes: the controller
alone, the test's own session publishing a centred person and the scan. No scan at all, or a
stale scan: never a forward command (turning in place stays allowed). The robot drives only
when the way is known clear. An obstacle within the safety distance is the obstacle
scenario's on real processes (test_scenarios.py, both modes); every case, with the distances,
runs in-process too (tests/unit/controller/test_loop.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial

import numpy as np
import pytest

from common.messages import ControllerStatus, LaserScan, ServiceCounters, Twist
from tests.integration.conftest import Stack, wait_for
from tests.integration.feeder import Feeder, all_clear, header, people

pytestmark = pytest.mark.integration

TICKS = 30  # statuses judged in each case: a second and a half at 20 Hz


def obstacle_ahead(distance_m: float, age_s: float = 0.0) -> bytes:
    """A 270 deg scan that sees a wall ``distance_m`` straight ahead (+-10 deg), and nothing
    else within range."""
    angles = np.linspace(-math.radians(135), math.radians(135), 541)
    ranges = np.full(541, np.inf, np.float32)
    ranges[np.abs(angles) <= math.radians(10)] = distance_m
    return LaserScan(
        header=header(age_s), angle_min=float(angles[0]),
        angle_increment=float(angles[1] - angles[0]), range_min=0.05, range_max=12.0,
        ranges=ranges,
    ).encode()  # fmt: skip


def person_and_scan(
    front: str, scan: str, distance_m: float, age_s: float = 0.0
) -> dict[str, bytes]:
    """A centred person in front and a scan with an obstacle ``distance_m`` ahead."""
    return {front: people(1), scan: obstacle_ahead(distance_m, age_s)}


def unannounced(raw: list[bytes]) -> int:
    """The controller's latest count of detections of a camera not announced."""
    return ServiceCounters.decode(raw[-1]).counters.get("detections_unannounced", 0) if raw else 0


def forward(raw: list[bytes], start: int = 0) -> list[Twist]:
    return [t for t in map(Twist.decode, list(raw)[start:]) if t.linear[0] > 0]


def statuses(raw: list[bytes], start: int = 0) -> list[ControllerStatus]:
    return [ControllerStatus.decode(s) for s in list(raw)[start:]]


def test_track_mode_never_drives_into_an_obstacle_or_blind(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(
        supervisor={"services": ["controller"]},
        controller={"mode": "track", "no_laser": False},
    )
    s = stack.config.controller
    stack.wait_ready({"controller"})
    stack.announce()  # the test stands in for the camera and the detector
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, status_raw = stack.subscribe(stack.keys.controller_status())
    front, scan = stack.keys.detections("front"), stack.keys.scan()
    stale_s = s.scan_timeout_s + 1.0
    # Each case makes its inputs afresh every round (the detections are stamped as they go).
    cases: dict[str, Callable[[], dict[str, bytes]]] = {
        "no scan": lambda: {front: people(1)},
        f"a scan {stale_s:.1f} s old": partial(person_and_scan, front, scan, 8.0, stale_s),
    }
    feeder = Feeder(stack)
    try:
        for case, inputs in cases.items():
            since_cmds, since = len(cmds), len(status_raw)
            feeder.feed(inputs)
            wait_for(lambda since=since: len(status_raw) > since + TICKS, 30, f"ticks with {case}")
            assert forward(cmds, since_cmds) == [], f"{case}: drove forward"
            # Once the person is seen (before: stale), every tick is blocked.
            seen = [x.state for x in statuses(status_raw, since)]
            assert "blocked" in seen, f"{case}: {seen}"
            assert set(seen[seen.index("blocked") :]) == {"blocked"}, f"{case}: {seen}"
        # Control: the same person with the way known clear is driven to.
        feeder.feed(lambda: {front: people(1), scan: all_clear()})
        wait_for(lambda: forward(cmds), 30, "forward motion with the way clear")
    finally:
        feeder.close()
    assert stack.stop() == 0, stack.log()


def test_without_a_laser_only_a_deliberate_setting_drives_and_every_status_says_so(
    make_stack,
) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(
        supervisor={"services": ["controller"]},
        controller={"mode": "track", "no_laser": True},
    )
    stack.wait_ready({"controller"})
    token = stack.announce()  # the test stands in for the camera and the detector
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, status_raw = stack.subscribe(stack.keys.controller_status())
    _, counts = stack.subscribe(stack.keys.counters("controller"))
    front, scan = stack.keys.detections("front"), stack.keys.scan()
    feeder = Feeder(stack)
    try:
        feeder.feed(lambda: {front: people(1)})
        wait_for(lambda: forward(cmds), 30, "forward motion with no laser, as set")
        # The camera's announcement withdrawn (its source gone) while its detections still
        # come: a stop at once, then nothing moves on them.
        token.undeclare()
        gone = "the target's camera front is no longer announced"
        [stop] = wait_for(
            lambda: [x for x in statuses(status_raw) if x.reason == gone][:1], 30, "the stop"
        )
        wait_for(lambda: unannounced(counts) >= 10, 30, "the unannounced detections to be counted")
        after = [Twist.decode(c) for c in list(cmds)]
        after = [t for t in after if t.header.stamp_ns >= stop.header.stamp_ns]
        assert after and all(t.is_zero for t in after), "moved on an unannounced camera"
        stack.announce()  # announced again: used again
        since = len(cmds)
        wait_for(lambda: forward(cmds, since), 30, "forward motion once announced again")
        # A scan that does come is obeyed all the same.
        feeder.feed(partial(person_and_scan, front, scan, 0.2))
        since = len(status_raw)
        wait_for(
            lambda: "blocked" in [x.state for x in statuses(status_raw, since)],
            30,
            "the obstacle stop on a scan that came",
        )
        assert all(x.no_laser for x in statuses(status_raw)), "a status did not say no laser"
        wait_for(lambda: "NO LASER: forward motion unchecked" in stack.log(), 30, "the status line")
    finally:
        feeder.close()
    assert stack.stop() == 0, stack.log()
