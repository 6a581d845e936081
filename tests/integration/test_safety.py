"""Safety on real processes: who may move the robot, a stop that is never forgotten, fresh data
only, and no service outliving its supervisor. Each test fails on a stack without the property.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from common.boxes import Boxes
from common.clock import BOOT_ID, now
from common.messages import (
    ControllerStatus,
    Detections,
    EStop,
    Header,
    LaserScan,
    ServiceCounters,
    Twist,
)
from tests.integration.conftest import REPO, Stack, wait_for
from tools.launch import service_pids

pytestmark = pytest.mark.integration

STACK = {"camera", "detector", "controller", "metrics"}
HOUR_NS = 3600 * 10**9


def moving(raw: list[bytes], start: int = 0) -> list[Twist]:
    return [t for t in map(Twist.decode, list(raw)[start:]) if not t.is_zero]


def started_moving(stack: Stack) -> list[bytes]:
    """Wait for the whole stack, then for it to drive towards the cameraman: its commands (a
    subscriber with a callback lives on, as the session's, once its handle is dropped)."""
    stack.wait_ready(STACK)
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    wait_for(lambda: moving(cmds), 60, "motion towards the cameraman")
    return cmds


def pause(seconds: float) -> None:
    """Let the stack run for a while: the duration is the test condition, not a wait for one."""
    threading.Event().wait(seconds)


def header(stamp_ns: int, source: str = "camera", mono_ns: int = 0) -> Header:
    return Header(
        stamp_ns=stamp_ns,
        frame_id="camera",
        seq=1,
        source=source,
        mono_ns=mono_ns,
        boot_id=BOOT_ID if mono_ns else "",
    )


def person(h: Header, n: int = 1) -> Detections:
    """``n`` centred people (n=0: nothing) in a 640x480 image, as the detector would send."""
    return Detections(
        header=h,
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.tile(np.array([[280, 100, 360, 400]], np.float32), (n, 1)),
            scores=np.full(n, 0.9, np.float32),
            class_ids=np.zeros(n, np.int32),
        ),
        class_names=("person",) * n,
    )


def restart_controller(stack: Stack) -> None:
    """SIGKILL the controller and wait until the supervisor's new one is ready."""
    [pid] = service_pids("controller", stack.config_path)
    os.kill(pid, signal.SIGKILL)
    wait_for(
        lambda: [p for p in service_pids("controller", stack.config_path) if p != pid],
        30,
        "the supervisor to restart the controller",
    )
    wait_for(lambda: "controller" in stack.ready_services(), 60, "the new controller")


def counters(raw: list[bytes]) -> dict[str, int]:
    return ServiceCounters.decode(raw[-1]).counters if raw else {}


def test_estop_survives_a_killed_controller_and_a_restarted_stack(make_stack, tmp_path) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack()
    cmds = started_moving(stack)
    stack.estop("engage")
    engaged = len(cmds)

    restart_controller(stack)
    after_restart = len(cmds)
    wait_for(lambda: len(cmds) > after_restart + 40, 20, "commands of the restarted controller")
    assert moving(cmds, engaged) == [], "a command moved the robot while the e-stop was latched"
    assert stack.stop() == 0, stack.log()

    again = Stack(stack.config_path, tmp_path / "second.log")
    try:
        again.wait_ready(STACK)
        _, cmds2 = again.subscribe(again.keys.cmd_vel())
        _, statuses = again.subscribe(again.keys.controller_status())
        # The detector finds the cameraman on every frame: without the latch this would move.
        _, dets = again.subscribe(again.keys.detections("front"))
        wait_for(lambda: len(dets) > 10, 60, "detections on the restarted stack")
        assert moving(cmds2) == [], "the restarted stack forgot the e-stop"
        assert {ControllerStatus.decode(s).state for s in list(statuses)} == {"estop"}
        again.estop("release")
        wait_for(lambda: moving(cmds2), 30, "motion after an explicit release")
    finally:
        assert again.stop() == 0, again.log()


def test_stale_future_and_replayed_detections_never_move_the_robot(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(supervisor={"services": ["controller"]})
    stack.wait_ready({"controller"})
    stack.announce()  # the test stands in for the camera and the detector
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, counts = stack.subscribe(stack.keys.counters("controller"))
    pub = stack.session.declare_publisher(stack.keys.detections("front"))

    def send_for(seconds: float, make: object) -> int:
        """Put detections at 20 Hz for ``seconds``; returns where its commands start."""
        start = len(cmds)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            pub.put(make())  # type: ignore[operator]
            pause(0.05)
        return start

    def fresh() -> bytes:
        at = now()
        return person(header(at.wall_ns, mono_ns=at.mono_ns)).encode()

    # The control: fresh detections of a centred person move the robot.
    start = send_for(1.0, fresh)
    wait_for(lambda: moving(cmds, start), 10, "motion on fresh detections")
    at = now()
    nobody = at.wall_ns
    pub.put(person(header(nobody, mono_ns=at.mono_ns), n=0).encode())  # nobody in view: stop
    # The target is gone: the robot holds its aim briefly and slows to a stop.
    wait_for(
        lambda: [
            t for t in map(Twist.decode, list(cmds)) if t.input_stamp_ns == nobody and t.is_zero
        ],
        5,
        "a stop on the empty detections",
    )

    for name, offset in (("past", -HOUR_NS), ("future", HOUR_NS)):
        start = send_for(1.5, lambda o=offset: person(header(now().wall_ns + o)).encode())
        assert moving(cmds, start) == [], f"detections stamped an hour in the {name} moved it"

    # A replay: an old message again, after a newer one from the same source.
    at = now()
    old_stamp = at.wall_ns
    old = person(header(old_stamp, mono_ns=at.mono_ns)).encode()
    before = len(cmds)
    pub.put(old)
    wait_for(
        lambda: [t for t in moving(cmds, before) if t.input_stamp_ns == old_stamp],
        5,
        "motion on the original message",
    )
    at = now()
    pub.put(person(header(at.wall_ns, mono_ns=at.mono_ns), n=0).encode())  # newer: nobody
    wait_for(
        lambda: [
            t for t in map(Twist.decode, list(cmds)) if t.input_stamp_ns == at.wall_ns and t.is_zero
        ],
        5,
        "a stop on the newer message",
    )
    start = len(cmds)
    assert Twist.decode(cmds[-1]).is_zero
    send_for(0.6, lambda: old)
    assert moving(cmds, start) == [], "a replayed message moved the robot"

    wait_for(
        lambda: all(
            counters(counts).get(f"detections_{k}", 0) > 0 for k in ("stale", "future", "replay")
        ),
        5,
        lambda: f"the controller to count stale, future and replayed input: {counters(counts)}",
    )
    assert stack.stop() == 0, stack.log()


def test_no_moving_command_on_frames_captured_before_a_detector_pause(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack()
    cmds = started_moving(stack)
    [pid] = service_pids("detector", stack.config_path)
    paused_ns = time.time_ns()
    os.kill(pid, signal.SIGSTOP)
    try:
        pause(5.0)
    finally:
        os.kill(pid, signal.SIGCONT)
    resumed = len(cmds)
    resumed_ns = time.time_ns()
    wait_for(
        lambda: [t for t in moving(cmds, resumed) if t.input_stamp_ns > resumed_ns],
        60,
        "motion on frames captured after the pause",
    )
    old = [t for t in moving(cmds, resumed) if t.input_stamp_ns < paused_ns]
    assert old == [], f"{len(old)} moving commands on frames captured before the pause"
    assert stack.stop() == 0, stack.log()


def test_a_killed_supervisor_takes_every_service_with_it(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack()
    cmds = started_moving(stack)

    second = subprocess.run(
        [sys.executable, "-m", "deploy.supervisor", "--config", str(stack.config_path)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert second.returncode == 2, second.stderr
    lines = second.stderr.strip().splitlines()
    assert len(lines) == 1 and f"pid {stack.proc.pid}" in lines[0], second.stderr

    pids = {name: service_pids(name, stack.config_path) for name in STACK}
    assert all(len(p) == 1 for p in pids.values()), pids
    os.kill(stack.proc.pid, signal.SIGKILL)
    killed = time.monotonic()
    try:
        wait_for(
            lambda: not any(service_pids(name, stack.config_path) for name in STACK),
            2.0,
            lambda: (
                f"every service to stop: {[n for n in STACK if service_pids(n, stack.config_path)]}"
            ),
        )
        assert time.monotonic() - killed <= 2.0
        assert Twist.decode(cmds[-1]).is_zero, "the controller's last word was not a stop"
    finally:
        # Had the property failed, never leave orphans running the next tests' CPU down.
        for name in STACK:
            for pid in service_pids(name, stack.config_path):
                os.kill(pid, signal.SIGKILL)
        stack.proc.wait()


def test_the_robot_side_reports_a_second_command_source(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(
        supervisor={"services": ["sim", "controller"]},
        sim={"scenario": "no_target", "wait_for": ["controller"]},
    )
    stack.wait_ready({"sim", "controller"})
    _, counts = stack.subscribe(stack.keys.counters("sim"))
    wait_for(lambda: counters(counts), 10, "the simulator's counters")
    assert counters(counts).get("commands_from_several_sources", 0) == 0
    pub = stack.session.declare_publisher(stack.keys.cmd_vel())
    stop = Twist(header=header(now().wall_ns, source="teleop"), input_stamp_ns=0)
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        pub.put(stop.encode())
        pause(0.1)
    wait_for(
        lambda: counters(counts).get("commands_from_several_sources", 0) > 0,
        5,
        "the simulator to count commands from two sources",
    )
    assert stack.stop() == 0, stack.log()
    assert "another publisher on cmd_vel" in stack.log()


def _rogue_attack(stack: Stack, principal: str, seconds: float) -> None:
    """Valid credentials of another service: release the e-stop, drive, and clear the scan."""
    rogue = stack.open(principal)
    try:
        cmd = rogue.declare_publisher(stack.keys.cmd_vel())
        estop = rogue.declare_publisher(stack.keys.estop())
        scan = rogue.declare_publisher(stack.keys.scan())
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            at = now()
            h = header(at.wall_ns, source="rogue", mono_ns=at.mono_ns)
            estop.put(EStop(header=h, engaged=False, reason="rogue").encode())
            cmd.put(Twist(header=h, linear=(0.5, 0.0, 0.0), input_stamp_ns=at.wall_ns).encode())
            for _ in range(4):  # 200 Hz of all-clear scans
                clear = np.full(360, np.inf, np.float32)
                scan.put(
                    LaserScan(
                        header=h,
                        angle_min=-3.14,
                        angle_increment=0.0174,
                        range_min=0.05,
                        range_max=12.0,
                        ranges=clear,
                    ).encode()
                )
            pause(0.02)
    finally:
        rogue.close()


@pytest.mark.parametrize("auth", ["password", "certificate"])
def test_secure_profile_keeps_strangers_out_and_services_to_their_own_keys(
    make_stack, tmp_path: Path, auth: str
) -> None:  # type: ignore[no-untyped-def]
    import dataclasses

    from common.errors import ConfigError
    from common.zenoh_bus import open_session
    from deploy.credentials import generate
    from tests.integration.conftest import credentials_for, free_port

    creds, other = tmp_path / "credentials", tmp_path / "another-install"
    prefix = credentials_for(creds)
    generate(other)
    table = {"mode": "client", "auth": auth, "credentials_dir": str(creds)}
    if auth == "certificate":  # mutual TLS: every link encrypted, every process its own key
        table["endpoint"] = f"tls/127.0.0.1:{free_port()}"
    stack: Stack = make_stack(zenoh=table, stack={"prefix": prefix})
    stack.wait_ready(STACK)
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, statuses = stack.subscribe(stack.keys.controller_status())
    _, scans = stack.subscribe(stack.keys.scan())
    wait_for(lambda: moving(cmds), 60, "the secure stack working: motion")

    # No credentials, or those of another installation (other passwords, another CA): the
    # session cannot join.
    zenoh_s = stack.config.zenoh
    with pytest.raises(ConfigError):
        open_session(dataclasses.replace(zenoh_s, auth="none"), "observer")
    with pytest.raises(ConfigError):
        observer = stack.config.principal("observer")
        open_session(dataclasses.replace(zenoh_s, credentials_dir=str(other)), observer)
    # As a peer with no credentials it opens, alone: it sees no service and no command.
    stranger = open_session(dataclasses.replace(zenoh_s, mode="peer", auth="none"), "observer")
    try:
        heard: list[bytes] = []
        stranger.declare_subscriber(stack.keys.cmd_vel(), lambda s: heard.append(b""))
        replies = stranger.liveliness().get(stack.keys.all_health(), timeout=1.0)
        assert not [r for r in replies if r.ok is not None]
        pause(1.0)
        assert heard == []
    finally:
        stranger.close()

    stack.estop("engage")
    engaged = len(cmds)
    _rogue_attack(stack, "detector", 3.0)
    assert moving(cmds, engaged) == [], "a rogue command reached the robot"
    assert {ControllerStatus.decode(s).state for s in list(statuses)[-20:]} == {"estop"}
    assert [s for s in map(LaserScan.decode, list(scans)) if s.header.source == "rogue"] == []
    # The control: the rogue's session was connected and could use its own key.
    rogue = stack.open("detector")
    try:
        _, own = stack.subscribe(stack.keys.detections("front"))
        mine = rogue.declare_publisher(stack.keys.detections("front"))
        marker = person(header(now().wall_ns, source="rogue-control"))
        wait_for(
            lambda: (
                mine.put(marker.encode())
                or any(Detections.decode(d).header.source == "rogue-control" for d in list(own))
            ),
            10,
            "the detector principal's put on its own key",
        )
    finally:
        rogue.close()
    stack.estop("release")  # the e-stop principal may
    released = len(cmds)
    wait_for(lambda: moving(cmds, released), 30, "motion after the authorised release")
    assert stack.stop() == 0, stack.log()
