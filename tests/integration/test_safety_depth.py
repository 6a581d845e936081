"""A robot with a depth camera and no laser (``obstacle_sources = ["depth"]``) obeys the
forward-safety rules on real processes: the depth scan stage and the controller alone, the
test's own session
publishing a centred person and the camera's depth images (a level floor seen from the
camera's announced height, and an obstacle when asked), and never a laser scan. Fresh depth
that shows the way clear: forward motion. The depth stream gone quiet: no forward motion once
the newest depth is ``depth_timeout_s`` old, as on a stale scan. An obstacle in the depth
within the safety distance: no forward motion, and none after it leaves the view for the
camera's blind zone (the controller's memory). What the camera cannot see is not clear: an
image with no floor in it, a dark box or pole that reads nothing, a step down whose edge is in
the blind zone. Every case with the figures runs in-process too
(tests/unit/controller/test_loop_depth.py, test_depth_hazards.py, test_local_map.py)."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable

import numpy as np
import pytest

from common.clock import now
from common.messages import ControllerStatus, LaserScan, Twist
from perception.depth import Intrinsics
from tests.integration.conftest import Stack, wait_for
from tests.integration.feeder import Feeder, header, people
from tests.unit.depthscan.depth_scenes import Face, at_bearing, depth_frame, scene
from tools.launch import service_pids

pytestmark = pytest.mark.integration

HEIGHT = 0.6  # the camera's optical centre above the floor, as announced
INTR = Intrinsics.from_hfov(320, 240, 60.0)  # a small image: 150 KB a frame
TICKS = 30  # statuses judged in a case: a second and a half at 20 Hz
#: The supervisor's wait before it restarts a killed depth scan stage, in the test of its death.
RESTART_S = 5.0


def forward(raw: list[bytes], start: int = 0) -> list[Twist]:
    return [t for t in map(Twist.decode, list(raw)[start:]) if t.linear[0] > 0]


def statuses(raw: list[bytes], start: int = 0) -> list[ControllerStatus]:
    return [ControllerStatus.decode(s) for s in list(raw)[start:]]


def on_fresh_depth(raw: list[bytes], start: int = 0) -> list[str]:
    """The reasons of the statuses from ``start`` on whose tick had fresh depth: on a loaded
    machine a test's feeder may fall behind, and a tick then blocks on the depth's age ("no
    recent depth": no motion either), which says nothing of what the depth shows."""
    return [x.reason for x in statuses(raw, start) if not x.reason.startswith("no recent depth")]


def on_fresh_scans(raw: list[bytes], start: int = 0) -> list[str]:
    """As :func:`on_fresh_depth`, but the ticks on a stale memory are kept: only those on a
    camera's stale virtual scan (the test's feeder behind) are left out."""
    return [
        x.reason for x in statuses(raw, start) if not x.reason.startswith("no recent depth from ")
    ]


def depth_robot(  # type: ignore[no-untyped-def]
    make_stack, restart_backoff_s: float = 0.2
) -> tuple[Stack, list[bytes], list[bytes]]:
    """A controller in track mode whose obstacles are the depth camera's (made into virtual
    scans by the depth scan stage beside it), the camera
    announced with depth by the test's session (which stands in for the camera, the detector
    and a robot with no laser); its commands and statuses as they come."""
    stack: Stack = make_stack(
        supervisor={
            "services": ["depthscan", "controller"],
            "restart_backoff_s": restart_backoff_s,
        },
        controller={"mode": "track", "no_laser": False, "obstacle_sources": ["depth"]},
    )
    stack.wait_ready({"depthscan", "controller"})
    stack.announce(depth=True, mount_height_m=HEIGHT, hfov_deg=60.0)
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, status_raw = stack.subscribe(stack.keys.controller_status())
    return stack, cmds, status_raw


def test_without_a_laser_the_depth_camera_shows_the_way_or_nothing_moves_forward(
    make_stack,
) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(
        supervisor={"services": ["depthscan", "controller"]},
        controller={"mode": "track", "no_laser": False, "obstacle_sources": ["depth"]},
    )
    s = stack.config.controller
    stack.wait_ready({"depthscan", "controller"})
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
        # The obstacle gone from view, but its place (0.4 m ahead) is in the camera's blind
        # zone (it sees the floor from 1.39 m): never seen clear, so remembered (issue 38).
        # Before the memory, the robot drove on at once.
        since_cmds, since = len(cmds), len(status_raw)
        feeder.feed(person_and_depth(clear))
        seen = lambda: on_fresh_depth(status_raw, since + TICKS)  # noqa: E731
        wait_for(lambda: len(seen()) >= TICKS, 60, "ticks with the floor seen")
        assert forward(cmds, since_cmds) == [], "drove into what slipped into the blind zone"
        said = set(seen())
        assert said and all(r.startswith("obstacle at 0.") for r in said), said
        assert all(r.endswith("(remembered)") for r in said), said
    finally:
        feeder.close()
    assert stack.stop() == 0, stack.log()


def _dark(image: np.ndarray, z_m: float) -> np.ndarray:
    out = image.copy()
    out[out == np.float32(z_m)] = np.nan  # reads nothing: black, or too dark to match
    return out


def _step(edge_m: float, depth_m: float) -> np.ndarray:
    upper, lower = scene(HEIGHT, intr=INTR), scene(HEIGHT + depth_m, intr=INTR)
    return np.where(upper < edge_m, upper, lower)


UNSEEN = {
    # Every pixel 10 m (the range's end): no floor where the camera's height says it shows.
    "no_floor": lambda: np.full((INTR.height, INTR.width), 10.0, np.float32),
    # A black box 0.5 m tall 1 m ahead: the floor beyond is seen above it.
    "black_box": lambda: _dark(scene(HEIGHT, Face(1.0, -0.3, 0.3, 0.0, 0.5), intr=INTR), 1.0),
    # A dark pole 0.45 m ahead at 25 deg: beside the camera's axis, inside the corridor.
    "dark_pole": lambda: _dark(scene(HEIGHT, at_bearing(0.45, 25.0, 0.02), intr=INTR), 0.45),
    # A step down 0.5 m deep whose edge (1.0 m ahead) is nearer than the floor is seen.
    "step_in_blind_zone": lambda: _step(1.0, 0.5),
}


@pytest.mark.parametrize("case", sorted(UNSEEN))
def test_what_the_depth_camera_cannot_see_is_not_clear(make_stack, case: str) -> None:  # type: ignore[no-untyped-def]
    # Issue 38: each of these images read clear before (the robot drove on at 0.05..0.3 m/s).
    stack, cmds, status_raw = depth_robot(make_stack)
    front, depth = stack.keys.detections("front"), stack.keys.depth("front")
    image = scene(HEIGHT, intr=INTR)

    def person_and_depth() -> dict[str, bytes]:
        return {front: people(1), depth: depth_frame(image, header(), INTR).encode()}

    feeder = Feeder(stack)
    try:
        feeder.feed(person_and_depth)  # control: the floor seen clear, driven on (creeping)
        wait_for(lambda: forward(cmds), 30, "forward motion with the floor seen clear")
        image = UNSEEN[case]()
        since_cmds, since = len(cmds), len(status_raw)
        seen = lambda: on_fresh_depth(status_raw, since + TICKS)  # noqa: E731
        wait_for(lambda: len(seen()) >= TICKS, 60, "ticks with the image")
        settled = statuses(status_raw, since + TICKS)
        first = settled[0].header.stamp_ns
        late = [t for t in forward(cmds, since_cmds) if t.header.stamp_ns >= first]
        assert late == [], f"{case}: drove forward {len(late)} times"
        said = set(seen())
        assert said and all(r.endswith("(depth)") for r in said), said
    finally:
        feeder.close()
    assert stack.stop() == 0, stack.log()


def _seen_into_the_blind_zone(stack: Stack, status_raw: list[bytes]) -> Feeder:
    """A box 0.4 m ahead (within the safety distance) seen, then gone from view into the
    blind zone: remembered. The feeder goes on with the clear floor and a centred person."""
    front, depth = stack.keys.detections("front"), stack.keys.depth("front")
    image = scene(HEIGHT, at_bearing(0.4, 0.0), intr=INTR)

    def person_and_depth() -> dict[str, bytes]:
        return {front: people(1), depth: depth_frame(image, header(), INTR).encode()}

    feeder = Feeder(stack)
    feeder.feed(person_and_depth)
    wait_for(lambda: said(status_raw, 0, "(depth)"), 30, "the obstacle seen in the depth")
    image = scene(HEIGHT, intr=INTR)
    since = len(status_raw)
    wait_for(lambda: said(status_raw, since, "(remembered)"), 30, "the obstacle remembered")
    return feeder


def stamps(raw: list[bytes]) -> list[int]:
    """The stamps (wall ns) of the scans put, as they came."""
    return [LaserScan.decode(m).header.stamp_ns for m in list(raw)]


def said(raw: list[bytes], start: int, end: str) -> list[ControllerStatus]:
    return [x for x in statuses(raw, start) if x.reason.endswith(end)]


def test_a_controller_restarted_after_a_crash_remembers_what_it_saw(make_stack) -> None:  # type: ignore[no-untyped-def]
    # A stop is not lost by a crash: what slipped into the blind zone stays an obstacle for
    # the controller the supervisor starts in place of a killed one (the depth scan stage,
    # which remembers it, runs on).
    stack, cmds, status_raw = depth_robot(make_stack)
    feeder = _seen_into_the_blind_zone(stack, status_raw)
    try:
        [pid] = service_pids("controller", stack.config_path)
        os.kill(pid, signal.SIGKILL)
        killed = len(status_raw)
        wait_for(
            lambda: [p for p in service_pids("controller", stack.config_path) if p != pid],
            30,
            "the supervisor to restart the controller",
        )

        def restarted() -> list[ControllerStatus]:
            """The statuses of the controller started in place of the killed one (its
            sequence numbers start again)."""
            after = statuses(status_raw, killed - 1)  # from the killed one's last
            seqs = [x.header.seq for x in after]
            new = [i for i in range(1, len(seqs)) if seqs[i] < seqs[i - 1]]
            return after[new[0] :] if new else []

        wait_for(lambda: len(restarted()) > 2 * TICKS, 60, "ticks of the restarted controller")
        settled = restarted()[TICKS:]
        first = settled[0].header.stamp_ns
        late = [t for t in forward(cmds) if t.header.stamp_ns >= first]
        assert late == [], f"the restarted controller drove forward {len(late)} times"
        reasons = {x.reason for x in settled}
        assert all(r.endswith("(remembered)") for r in reasons), reasons
    finally:
        feeder.close()
    assert stack.stop() == 0, stack.log()


def test_a_depth_scan_stage_restarted_after_a_crash_remembers_what_it_saw(make_stack) -> None:  # type: ignore[no-untyped-def]
    # The stage killed: the controller holds still while it is gone, and the stage the
    # supervisor starts in its place takes back what it remembered (its depth map on disk):
    # the box in the blind zone stays an obstacle, never seen clear since.
    stack, cmds, status_raw = depth_robot(make_stack)
    feeder = _seen_into_the_blind_zone(stack, status_raw)
    try:
        [pid] = service_pids("depthscan", stack.config_path)
        since_cmds = len(cmds)
        _, memories = stack.subscribe(stack.keys.remembered_scan())
        os.kill(pid, signal.SIGKILL)
        wait_for(
            lambda: [p for p in service_pids("depthscan", stack.config_path) if p != pid],
            30,
            "the supervisor to restart the depth scan stage",
        )
        # The killed stage is gone (the supervisor restarts a stage once it has exited): a
        # memory stamped from now on is the new stage's. Not the first "(remembered)" status
        # after the kill: the killed stage's last memory stays fresh for depth_timeout_s, and a
        # stage slow to start (seconds on a loaded machine) is not back within the ticks judged.
        restarted_ns = now().wall_ns

        def new() -> list[int]:
            return [m for m in stamps(memories) if m > restarted_ns]

        wait_for(new, 60, "the restarted stage's first memory")

        def back() -> list[int]:
            """The new stage's memory back: remembered again, and from then on only that."""
            return [
                i for i, x in enumerate(statuses(status_raw))
                if x.header.stamp_ns > min(new()) and x.reason.endswith("(remembered)")
            ]  # fmt: skip

        wait_for(back, 60, "the restarted stage's memory")
        start = back()[0] + TICKS
        wait_for(lambda: len(on_fresh_scans(status_raw, start)) >= TICKS, 60, "ticks after it")
        reasons = set(on_fresh_scans(status_raw, start))
        assert all(r.endswith("(remembered)") for r in reasons), reasons
        assert forward(cmds, since_cmds) == [], "drove forward after the stage was killed"
    finally:
        feeder.close()
    assert stack.stop() == 0, stack.log()
    assert "depth map" in stack.log() and "taken back" in stack.log(), stack.log()


@pytest.mark.parametrize("how", ["killed", "hung"])
def test_the_depth_scan_stage_gone_stops_the_robot_at_once(make_stack, how: str) -> None:  # type: ignore[no-untyped-def]
    # The stage killed (SIGKILL) or hung (SIGSTOP) while the robot drives on clear depth: no
    # command stamped later than depth_timeout_s after it went drives or turns (its virtual
    # scans and memory stale: the controller holds still at once, turning included).
    # The killed stage is restarted only after RESTART_S: the ticks between are what is judged.
    stack, cmds, status_raw = depth_robot(make_stack, restart_backoff_s=RESTART_S)
    timeout_ns = int(stack.config.controller.depth_timeout_s * 1e9)
    front, depth = stack.keys.detections("front"), stack.keys.depth("front")
    clear = scene(HEIGHT, intr=INTR)
    feeder = Feeder(stack)
    [pid] = service_pids("depthscan", stack.config_path)
    # The stage's memory as it is published: the first one stamped after the kill comes from
    # the stage the supervisor restarts (restart_backoff_s later), whose fresh scans may move
    # the robot again. What is judged is the time between: the stage gone, not yet back.
    _, memories = stack.subscribe(stack.keys.remembered_scan())
    try:
        feeder.feed(lambda: {front: people(1), depth: depth_frame(clear, header(), INTR).encode()})
        wait_for(lambda: forward(cmds), 30, "forward motion with the depth showing the way clear")
        gone_ns = now().wall_ns
        os.kill(pid, signal.SIGKILL if how == "killed" else signal.SIGSTOP)
        since = len(status_raw)
        late = gone_ns + timeout_ns

        def back_ns() -> int:
            """When the stage was back (its first memory stamped after the kill), or never."""
            stamps = [LaserScan.decode(m).header.stamp_ns for m in list(memories)]
            return min((t for t in stamps if t > gone_ns), default=2**63 - 1)

        def after() -> list[ControllerStatus]:
            return [x for x in statuses(status_raw, since) if late < x.header.stamp_ns < back_ns()]

        wait_for(
            lambda: len(after()) > TICKS or back_ns() < 2**63 - 1,
            30,
            "ticks after the stage went, or its restart",
        )
        quiet = after()
        assert len(quiet) >= 2, "no tick judged between the stage's going and its restart"
        moving = [
            t for t in map(Twist.decode, list(cmds))
            if late < t.header.stamp_ns < back_ns() and (t.linear[0] != 0 or t.angular[2] != 0)
        ]  # fmt: skip
        assert moving == [], f"{len(moving)} commands moved the robot with the stage {how}"
        assert {x.state for x in quiet} == {"blocked"}, [(x.state, x.reason) for x in quiet]
        assert all("depth" in x.reason for x in quiet), {x.reason for x in quiet}
        if how == "killed":  # and the supervisor brings it back: the stop ends a whole stack
            wait_for(lambda: back_ns() < 2**63 - 1, RESTART_S + 30, "the restarted stage")
    finally:
        if how == "hung":
            os.kill(pid, signal.SIGCONT)
        feeder.close()
    assert stack.stop() == 0, stack.log()
