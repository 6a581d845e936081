"""Depth from the announced source only (issue 38), on real processes: the depth scan stage
(which reads the depth and counts what it drops) and the controller, with
``obstacle_sources = ["depth"]``; the test's session stands in for the camera (it announces
it with depth and its own session id, and publishes a level floor with a box 0.4 m ahead,
within the safety distance) and the detector (a centred person). A second session forges the
camera's depth: a clear floor, 20 Hz, stamped 0.09 s ahead (within the cross-host clock
tolerance, as in the attack) and from "another host" (another boot id, so the same-clock
future check cannot catch it). Before the fix the forged frames were the newest, the real ones
were counted late and the robot drove through the box. Now: no forward motion, the forged
frames counted ``depth_foreign``, no real frame counted late, the box in the status."""

from __future__ import annotations

import threading

import pytest
import zenoh

from common.bus import QoS
from common.clock import now
from common.messages import ControllerStatus, Header, ServiceCounters
from common.zenoh_bus import Publisher
from perception.depth import Intrinsics
from tests.integration.conftest import Stack, wait_for
from tests.integration.feeder import PERIOD_S, Feeder, header, people
from tests.integration.test_safety_depth import forward, statuses
from tests.unit.depthscan.depth_scenes import at_bearing, depth_frame, scene

pytestmark = pytest.mark.integration

HEIGHT = 0.6
INTR = Intrinsics.from_hfov(320, 240, 60.0)
AHEAD_S = 0.09  # the forged stamps' lead, as in the attack
TICKS = 40  # two seconds of statuses at 20 Hz


def forged_header() -> Header:
    """Stamped AHEAD_S ahead, as from another host (another boot: only the wall clock judged)."""
    at = now()
    lead = int(AHEAD_S * 1e9)
    return Header(
        stamp_ns=at.wall_ns + lead, frame_id="camera", seq=1, source="camera",
        mono_ns=at.mono_ns + lead, boot_id="another-host",
    )  # fmt: skip


def stream(session: zenoh.Session, key: str, make: object, stop: threading.Event) -> None:
    """``make()``'s depth frame on ``key`` every PERIOD_S, from ``session`` with its source
    info (common/zenoh_bus.py's Publisher, as every service's)."""
    pub = Publisher(session, key, QoS.SENSOR)
    try:
        while not stop.wait(PERIOD_S):
            pub.put(make().encode())  # type: ignore[operator]
    finally:
        pub.undeclare()


def test_a_forged_clear_depth_stream_stamped_ahead_does_not_hide_the_real_box(
    make_stack,
) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(
        supervisor={"services": ["depthscan", "controller"]},
        controller={"mode": "track", "no_laser": False, "obstacle_sources": ["depth"]},
    )
    stack.wait_ready({"depthscan", "controller"})
    zid = str(stack.session.info.zid())
    stack.announce(depth=True, mount_height_m=HEIGHT, hfov_deg=60.0, zid=zid)
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, status_raw = stack.subscribe(stack.keys.controller_status())
    _, counters_raw = stack.subscribe(stack.keys.counters("depthscan"))
    depth_key = stack.keys.depth(stack.config.stack.camera)
    boxed = scene(HEIGHT, at_bearing(0.4, 0.0), intr=INTR)
    clear = scene(HEIGHT, intr=INTR)
    forger = stack.open("forger")
    stop = threading.Event()
    threads = [
        threading.Thread(
            target=stream,
            args=(stack.session, depth_key, lambda: depth_frame(boxed, header(), INTR), stop),
        ),
        threading.Thread(
            target=stream,
            args=(forger, depth_key, lambda: depth_frame(clear, forged_header(), INTR), stop),
        ),
    ]
    feeder = Feeder(stack)
    try:
        feeder.feed(lambda: {stack.keys.detections("front"): people(1)})
        for thread in threads:
            thread.start()
        wait_for(
            lambda: [x for x in statuses(status_raw) if x.reason.endswith("(depth)")][:1],
            30,
            "the real box seen in the depth",
        )
        since, since_cmds = len(status_raw), len(cmds)
        wait_for(lambda: len(status_raw) > since + TICKS, 30, "ticks with both streams")
        assert forward(cmds, since_cmds) == [], "drove on the forged clear depth"
        seen: list[ControllerStatus] = statuses(status_raw, since)
        assert {x.state for x in seen} == {"blocked"}, [(x.state, x.reason) for x in seen]

        def counted() -> dict[str, int] | None:
            last = [ServiceCounters.decode(c).counters for c in list(counters_raw)[-1:]]
            return last[0] if last and last[0].get("depth_foreign.front", 0) >= 10 else None

        totals = wait_for(counted, 30, "the forged frames counted")
        assert totals.get("depth_in.front", 0) >= 10, totals
        assert totals.get("depth_late.front", 0) == 0, totals  # the real frames not displaced
    finally:
        stop.set()
        for thread in threads:
            if thread.is_alive():
                thread.join(5)
        feeder.close()
        forger.close()
    log = stack.log_path.read_text(errors="replace")  # the WARNING, once the flood began
    assert "not by the session that announced the camera" in log, stack.log()
    assert stack.stop() == 0, stack.log()
