"""A robot with a depth camera and no laser (``obstacle_sources = ["depth"]``) obeys the
forward-safety rules on real processes: the controller alone, the test's own session
publishing a centred person and the camera's depth images (a level floor seen from the
camera's announced height, and an obstacle when asked), and never a laser scan. Fresh depth
that shows the way clear: forward motion. The depth stream gone quiet: no forward motion once
the newest depth is ``depth_timeout_s`` old, as on a stale scan. An obstacle in the depth
within the safety distance: no forward motion. Every case with the figures runs in-process
too (tests/unit/controller/test_loop_depth.py)."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from common.messages import ControllerStatus, Twist
from perception.depth import Intrinsics
from tests.integration.conftest import Stack, wait_for
from tests.integration.feeder import Feeder, header, people
from tests.unit.controller.depth_scenes import at_bearing, depth_frame, scene

pytestmark = pytest.mark.integration

HEIGHT = 0.6  # the camera's optical centre above the floor, as announced
INTR = Intrinsics.from_hfov(320, 240, 60.0)  # a small image: 150 KB a frame
TICKS = 30  # statuses judged in a case: a second and a half at 20 Hz


def forward(raw: list[bytes], start: int = 0) -> list[Twist]:
    return [t for t in map(Twist.decode, list(raw)[start:]) if t.linear[0] > 0]


def statuses(raw: list[bytes], start: int = 0) -> list[ControllerStatus]:
    return [ControllerStatus.decode(s) for s in list(raw)[start:]]


def test_without_a_laser_the_depth_camera_shows_the_way_or_nothing_moves_forward(
    make_stack,
) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(
        supervisor={"services": ["controller"]},
        controller={"mode": "track", "no_laser": False, "obstacle_sources": ["depth"]},
    )
    s = stack.config.controller
    stack.wait_ready({"controller"})
    # The test stands in for the camera (with depth), the detector, and a robot with no laser.
    stack.announce(depth=True, mount_height_m=HEIGHT, hfov_deg=60.0)
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, status_raw = stack.subscribe(stack.keys.controller_status())
    front, depth = stack.keys.detections("front"), stack.keys.depth("front")
    clear = scene(HEIGHT, intr=INTR)
    blocked = scene(HEIGHT, at_bearing(0.4, 0.0), intr=INTR)  # within the safety distance
    depth_stamps: list[int] = []

    def person_and_depth(image: object) -> Callable[[], dict[str, bytes]]:
        def make() -> dict[str, bytes]:
            frame = depth_frame(image, header(), INTR)  # type: ignore[arg-type]
            depth_stamps.append(frame.header.stamp_ns)
            return {front: people(1), depth: frame.encode()}

        return make

    feeder = Feeder(stack)
    try:
        # Fresh depth that shows the way clear: driven to.
        feeder.feed(person_and_depth(clear))
        wait_for(lambda: forward(cmds), 30, "forward motion with the depth showing the way clear")
        # The depth stream goes quiet while the person is still seen: once the newest depth
        # is depth_timeout_s old, never again a tick that drives on (the speed then ramps
        # down at the deceleration limit, as on a stale scan), and soon no forward command.
        since = len(status_raw)
        feeder.feed(lambda: {front: people(1)})  # returns once no round with depth is left
        last = max(depth_stamps)
        stale_at = last + int(s.depth_timeout_s * 1e9)
        wait_for(
            lambda: (
                len([x for x in statuses(status_raw, since) if x.header.stamp_ns > stale_at])
                > TICKS
            ),
            30,
            "ticks after the depth went stale",
        )
        quiet = [x for x in statuses(status_raw, since) if x.header.stamp_ns > stale_at]
        assert {x.state for x in quiet} == {"blocked"}, [(x.state, x.reason) for x in quiet]
        assert quiet[-1].reason.startswith("no recent depth from front"), quiet[-1].reason
        ramp_ns = int((s.forward_speed / s.max_linear_accel + 0.2) * 1e9)
        late = [t for t in forward(cmds) if t.header.stamp_ns > stale_at + ramp_ns]
        assert late == [], f"drove forward {len(late)} times on depth gone stale"
        # An obstacle in the depth, 0.4 m ahead: no forward motion at all, the status says why.
        since_cmds, since = len(cmds), len(status_raw)
        feeder.feed(person_and_depth(blocked))
        wait_for(
            lambda: [x for x in statuses(status_raw, since) if x.reason.endswith("(depth)")][:1],
            30,
            "the obstacle seen in the depth",
        )
        wait_for(lambda: len(status_raw) > since + TICKS, 30, "ticks with the obstacle")
        assert forward(cmds, since_cmds) == [], "drove towards an obstacle the depth shows"
        said = {x.reason for x in statuses(status_raw, since) if x.reason.endswith("(depth)")}
        assert said and all(r.startswith("obstacle at 0.") for r in said), said
        # Control: the obstacle gone, the way clear again, driven to again.
        since_cmds = len(cmds)
        feeder.feed(person_and_depth(clear))
        wait_for(lambda: forward(cmds, since_cmds), 30, "forward motion once the way is clear")
    finally:
        feeder.close()
    assert stack.stop() == 0, stack.log()
