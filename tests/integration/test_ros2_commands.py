"""The last hop before the wheels: the bridge sends the robot only fresh, ordered commands from
the controller, and zero while the e-stop is engaged or the controller is silent (issue 29).

One stack (the bridge and the controller). The test stands in for the detector (a centred
person, so the controller drives) and for the robot (an rmw_zenoh router, and a node on
/cmd_vel decoding with rosbags). The robot takes TwistStamped, so each command it gets names,
by its stamp, the stack Twist it came from; the bridge's own stops are stamped when sent.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from common.clock import BOOT_ID
from common.messages import Header, ServiceCounters, Twist
from tests.integration.conftest import Stack, free_port, publish_cameras, wait_for
from tests.integration.test_ros2 import RobotSide
from tools.launch import service_pids

pytestmark = pytest.mark.integration

TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
SERVICES = {"controller", "ros2"}
HOUR_NS = 3600 * 10**9


def _centred(w: int, h: int) -> tuple[float, float, float, float]:
    return (0.45 * w, 0.2 * h, 0.55 * w, 0.9 * h)


def _forged(stamp_ns: int, *, mono_ns: int = 0, boot_id: str = "") -> Twist:
    """A command that says it is the controller's, moving as the controller never does."""
    header = Header(stamp_ns=stamp_ns, frame_id="base_link", seq=1, source="controller",
                    mono_ns=mono_ns, boot_id=boot_id)  # fmt: skip
    return Twist(header=header, linear=(0.4, 0.0, 0.0), angular=(0.0, 0.0, 0.77))


def _fresh_forgery() -> Twist:
    """Stamped now on both clocks of this host, as the controller stamps its own."""
    return _forged(time.time_ns(), mono_ns=time.monotonic_ns(), boot_id=BOOT_ID)


def test_the_robot_gets_only_fresh_ordered_commands_from_the_controller(
    make_stack, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robot = RobotSide(endpoint)
    stop = threading.Event()
    got: list[tuple[int, float, float]] = []  # what the robot got: (stamp_ns, v, w), in order

    def on_cmd_vel(sample: Any) -> None:
        msg = robot.ts.deserialize_cdr(sample.payload.to_bytes(), TWIST_STAMPED)
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        got.append((stamp, msg.twist.linear.x, msg.twist.angular.z))

    robot.node.declare_subscriber(robot.key("cmd_vel", TWIST_STAMPED), on_cmd_vel)
    controller_pid = 0
    try:
        stack: Stack = make_stack(
            supervisor={"services": sorted(SERVICES)},
            ros2={"router": [endpoint], "twist_stamped": True, "image_in": False,
                  "scan_in": False, "detections_out": False},
        )  # fmt: skip
        stack.wait_ready(SERVICES)
        _, sent = stack.subscribe(stack.keys.cmd_vel())  # the controller's, as it put them
        _, counts = stack.subscribe(stack.keys.counters("ros2"))
        rogue = stack.session.declare_publisher(stack.keys.cmd_vel())
        threading.Thread(
            target=publish_cameras,
            args=(stack, stop, {"front": ((160, 120), "person")}),
            kwargs={"fill": 0, "box": _centred, "score": 0.9},
            daemon=True,
        ).start()

        def counters() -> dict[str, int]:
            return ServiceCounters.decode(counts[-1]).counters if counts else {}

        def refused() -> int:
            c = counters()
            return sum(c.get(f"commands_{v}", 0) for v in ("stale", "future", "replay"))

        def reached(stamp_ns: int) -> list[tuple[int, float, float]]:
            return [g for g in list(got) if g[0] == stamp_ns]

        def moving(after_ns: int = 0) -> list[tuple[int, float, float]]:
            return [g for g in list(got) if g[0] > after_ns and (g[1] or g[2])]

        def put(twists: list[Twist], refusals: int, what: str) -> None:
            """Put ``twists`` on the stack's cmd_vel and wait until the bridge has refused
            ``refusals`` more or sent each on; none may reach the robot moving."""
            before = refused()
            had = {t.header.stamp_ns: len(reached(t.header.stamp_ns)) for t in twists}
            for twist in twists:
                rogue.put(twist.encode())
            wait_for(
                lambda: (
                    refused() >= before + refusals
                    or all(len(reached(s)) > n for s, n in had.items())
                ),
                30,
                lambda: f"the bridge to deal with {what} (counters {counters()})",
            )
            for stamp, n in had.items():
                new = reached(stamp)[n:]
                assert not [g for g in new if g[1] or g[2]], f"{what} reached the robot: {new}"

        def forge_until_sent(what: str) -> None:
            """Put fresh forgeries, stamped as the controller stamps its own, until one is
            sent on (one may lose the race with the controller's next, newer, command and be
            refused as a replay): it must reach the robot as zero."""
            stamps: set[int] = set()

            def attempt() -> list[tuple[int, float, float]]:
                forgery = _fresh_forgery()
                stamps.add(forgery.header.stamp_ns)
                rogue.put(forgery.encode())
                return [g for g in list(got) if g[0] in stamps]

            through = wait_for(attempt, 30, lambda: f"{what} sent on ({counters()})", poll=0.2)
            assert not [g for g in through if g[1] or g[2]], f"{what} reached the robot: {through}"

        wait_for(moving, 90, lambda: f"the controller moving the robot ({stack.log()})")

        # 1. Stamped 60 s old, 1 h old, 1 h ahead, 0: refused, never sent on.
        t = time.time_ns()
        forged = [_forged(t - 60 * 10**9), _forged(t - HOUR_NS), _forged(t + HOUR_NS), _forged(0)]
        put(forged, len(forged), "Twists 60 s old, 1 h old, 1 h ahead or stamped 0")
        assert counters().get("commands_stale", 0) >= 3 and counters().get("commands_future"), (
            counters()
        )

        # 2. A controller command played again out of order, well within the window: the
        # robot got it once, when it was new.
        def newest_moving() -> Twist | None:
            twists = (Twist.decode(p) for p in reversed(list(sent)))
            return next(
                (tw for tw in twists if not tw.is_zero and reached(tw.header.stamp_ns)), None
            )

        replayed = wait_for(
            newest_moving, 30, "a moving command of the controller's that the robot got"
        )
        put([replayed], 1, "a replayed command")

        # 3. The e-stop engaged: a 9 s old command, and a fresh one stamped as the controller
        # stamps its own, reach the robot as zero or not at all.
        oldest = Twist.decode(next(p for p in sent if not Twist.decode(p).is_zero))
        stack.estop("engage")
        engaged_ns = time.time_ns()
        wait_for(lambda: time.time_ns() - oldest.header.stamp_ns > 9 * 10**9, 20, "9 s to pass")
        put([oldest], 1, "an old command during the e-stop")
        forge_until_sent("a fresh command during the e-stop")
        assert not moving(engaged_ns), f"the robot moved during the e-stop: {moving(engaged_ns)}"
        stack.estop("release")
        released_ns = time.time_ns()
        wait_for(lambda: moving(released_ns), 30, "the controller moving the robot again")

        # 4. The controller silent (frozen): the robot is sent zero, and a fresh command stamped
        # as the controller's goes out as zero.
        [controller_pid] = service_pids("controller", stack.config_path)
        os.kill(controller_pid, signal.SIGSTOP)
        silent_ns = time.time_ns()
        wait_for(
            lambda: any(g[0] > silent_ns and not (g[1] or g[2]) for g in list(got)),
            20,
            "the bridge to send the robot zero when the controller went silent",
        )
        forge_until_sent("a fresh command while the controller is silent")
        assert not moving(silent_ns), (
            f"the robot moved with the controller silent: {moving(silent_ns)}"
        )
        os.kill(controller_pid, signal.SIGCONT)
        controller_pid = 0

        # Over the whole run, what moved the robot came in order.
        stamps = [g[0] for g in moving()]
        assert stamps == sorted(set(stamps)), "moving commands reached the robot out of order"
        assert stack.stop() == 0, stack.log()
    finally:
        stop.set()
        if controller_pid:
            with contextlib.suppress(ProcessLookupError):
                os.kill(controller_pid, signal.SIGCONT)
        robot.close()
