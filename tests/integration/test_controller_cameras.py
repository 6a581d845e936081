"""The controller with two cameras (front 0 deg, rear 180 deg) on real processes, without the
simulator: the test's own session publishes each camera's detections and the scan, and reads
cmd_vel, the status and the counters. A person seen only by the rear camera turns the robot
round in place; silence stops it within the dead-man timeout; a stale camera is never trusted.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable

import numpy as np
import pytest

from common.clock import BOOT_ID, now
from common.messages import ControllerStatus, Header, LaserScan, ServiceCounters, Twist
from tests.integration.conftest import Stack, wait_for
from tests.integration.test_safety import person

pytestmark = pytest.mark.integration

PERIOD_S = 0.05  # how often the test publishes, as a 20 Hz detector and laser would
TWO_CAMERAS = {"cameras.rear": {"mount_yaw_deg": 180.0}}


def header(age_s: float = 0.0) -> Header:
    """Stamped ``age_s`` ago on both clocks, as the detector passes a frame's on."""
    at = now()
    ago = int(age_s * 1e9)
    return Header(
        stamp_ns=at.wall_ns - ago, frame_id="camera", seq=1, source="detector",
        mono_ns=at.mono_ns - ago, boot_id=BOOT_ID,
    )  # fmt: skip


def people(n: int, age_s: float = 0.0) -> bytes:
    """``n`` people (0: nobody) centred in a 640x480 image."""
    return person(header(age_s), n).encode()


def all_clear() -> bytes:
    """A 270 deg scan that sees nothing within range (the simulator's laser has no ray behind)."""
    return LaserScan(
        header=header(), angle_min=-math.radians(135), angle_increment=math.radians(270) / 540,
        range_min=0.05, range_max=12.0, ranges=np.full(541, np.inf, np.float32),
    ).encode()  # fmt: skip


class Feeder:
    """Publishes what ``make`` returns (key -> payload) every PERIOD_S on a thread of its
    own, until switched to another ``make`` or to nothing."""

    def __init__(self, stack: Stack) -> None:
        self.stack = stack
        self.pubs: dict[str, object] = {}
        self.make: Callable[[], dict[str, bytes]] | None = None
        self.last_put_ns = 0  # no capture stamp of the last round put is older (wall ns)
        self.done = threading.Event()
        self.lock = threading.Lock()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def feed(self, make: Callable[[], dict[str, bytes]] | None) -> None:
        with self.lock:
            self.make = make

    def _run(self) -> None:
        while not self.done.wait(PERIOD_S):
            with self.lock:
                if self.make is None:
                    continue
                before = now().wall_ns  # no capture stamp in this round is older
                for key, payload in self.make().items():
                    if key not in self.pubs:
                        self.pubs[key] = self.stack.session.declare_publisher(key)
                    self.pubs[key].put(payload)  # type: ignore[attr-defined]
                self.last_put_ns = before

    def close(self) -> None:
        self.done.set()
        self.thread.join(5)


def states_since(statuses: list[bytes], start: int) -> list[ControllerStatus]:
    return [ControllerStatus.decode(s) for s in list(statuses)[start:]]


def counter(counts: list[bytes], name: str) -> int:
    return ServiceCounters.decode(counts[-1]).counters.get(name, 0) if counts else 0


def test_a_person_seen_only_by_the_rear_camera_turns_the_robot_round(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(supervisor={"services": ["controller"]}, **TWO_CAMERAS)
    assert list(stack.config.all_cameras) == ["front", "rear"]
    timeout_s = stack.config.controller.detection_timeout_s
    stack.wait_ready({"controller"})
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, statuses = stack.subscribe(stack.keys.controller_status())
    _, counts = stack.subscribe(stack.keys.counters("controller"))
    front, rear = stack.keys.detections("front"), stack.keys.detections("rear")
    scan = stack.keys.scan()
    feeder = Feeder(stack)
    try:
        # 1. A person centred in the rear camera only (bearing 180 deg, wrapped to +180: a
        # left turn), the front camera silent: the robot turns in place, towards the rear.
        feeder.feed(lambda: {rear: people(1), scan: all_clear()})
        wait_for(
            lambda: [t for t in map(Twist.decode, list(cmds)) if t.angular[2] > 0.1],
            30,
            "a turn towards the person behind",
        )
        turning = [t for t in map(Twist.decode, list(cmds)) if not t.is_zero]
        assert all(t.angular[2] > 0 and t.linear[0] == 0.0 for t in turning), turning[:5]
        [status, *_] = wait_for(
            lambda: [s for s in states_since(statuses, 0) if s.state == "turning"],
            10,
            "the status of the turn",
        )
        assert status.camera == "rear", status
        assert status.stale_cameras == ("front",), "the silent front camera is not named stale"

        # 2. Silence: no moving command is stamped later than the detection timeout after the
        # last detections' capture, and the status says both cameras are stale.
        feeder.feed(None)
        last_capture_ns = feeder.last_put_ns
        since_cmds, since_status = len(cmds), len(statuses)
        [status, *_] = wait_for(
            lambda: [s for s in states_since(statuses, since_status) if s.state == "stale"],
            10,
            "the dead-man stop",
        )
        assert status.stale_cameras == ("front", "rear"), status
        late = [
            t
            for t in map(Twist.decode, list(cmds)[since_cmds:])
            if not t.is_zero and t.header.stamp_ns > last_capture_ns + int(timeout_s * 1e9)
        ]
        assert late == [], f"{len(late)} moving commands after the detection timeout"
        assert Twist.decode(cmds[-1]).is_zero
        stopped = len(cmds)

        # 3. Stale detections of a person on the rear key, beside fresh empty ones in front:
        # the rear camera is ignored (and named), nothing moves.
        stale = 2 * timeout_s
        feeder.feed(lambda: {rear: people(1, stale), front: people(0), scan: all_clear()})
        since_status = len(statuses)
        wait_for(
            lambda: [
                s
                for s in states_since(statuses, since_status)
                if s.state == "searching" and s.stale_cameras == ("rear",)
            ],
            10,
            "the front camera fresh and the rear one named stale",
        )
        # 4. Only the stale rear camera: the dead-man stop, and the stale input counted.
        feeder.feed(lambda: {rear: people(1, stale), scan: all_clear()})
        since_status = len(statuses)
        wait_for(
            lambda: [s for s in states_since(statuses, since_status) if s.state == "stale"],
            10,
            "the dead-man stop on stale detections only",
        )
        wait_for(
            lambda: counter(counts, "detections_stale.rear") > 0,
            10,
            "the rear camera's stale detections to be counted",
        )
        moved = [t for t in map(Twist.decode, list(cmds)[stopped:]) if not t.is_zero]
        assert moved == [], f"stale detections moved the robot: {moved[:3]}"
        assert counter(counts, "detections_in.rear") > 0 and counter(counts, "detections_in") > 0
    finally:
        feeder.close()
    assert stack.stop() == 0, stack.log()
