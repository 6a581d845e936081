"""The e-stop latch on real processes when its state cannot be saved or read, and when its
stamps lie: a stop that cannot be saved is still a stop (and is never reported as durable),
a corrupt state is engaged (never a crash), and a stamp a century ahead cannot latch for good.
"""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from common.clock import now
from common.messages import ControllerStatus, EStop, Twist
from tests.integration.conftest import REPO, Stack, wait_for
from tests.integration.test_safety import STACK, header, moving, pause, restart_controller
from tools.launch import free_port

pytestmark = pytest.mark.integration

CENTURY_NS = 100 * 365 * 86400 * 10**9


def estop_cli(stack: Stack, action: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "services.controller", "estop", action,
         "--config", str(stack.config_path), "--reason", "test"],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip


@contextlib.contextmanager
def unwritable(folder: Path) -> Iterator[None]:
    """``folder`` immutable (chattr +i: even root cannot create, rename or delete in it),
    as the attack made the controller's state folder; undone whatever happens."""
    subprocess.run(["chattr", "+i", str(folder)], check=True)
    try:
        probe = folder / "probe"
        with pytest.raises(OSError):
            probe.write_text("")  # the condition holds: nothing can be written there
        yield
    finally:
        subprocess.run(["chattr", "-i", str(folder)], check=True)


def statuses_of(raw: list[bytes]) -> list[ControllerStatus]:
    return [ControllerStatus.decode(s) for s in list(raw)]


def test_a_stop_that_cannot_be_saved_is_still_a_stop(make_stack, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    state = tmp_path / "state"
    state.mkdir()
    stack: Stack = make_stack(controller={"estop_file": str(state / "estop.json")})
    stack.wait_ready(STACK)
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, statuses = stack.subscribe(stack.keys.controller_status())
    wait_for(lambda: moving(cmds), 60, "motion towards the cameraman")
    with unwritable(state):
        # The engage stops the robot, but the CLI must not call it durable.
        done = estop_cli(stack, "engage")
        assert done.returncode == 1, done.stdout + done.stderr
        assert "could NOT save the stop" in done.stderr and "e-stop engaged" not in done.stdout
        engaged = len(cmds)
        # A release that cannot be saved is refused, and the CLI says so truly.
        done = estop_cli(stack, "release")
        assert done.returncode == 1 and "refused the release" in done.stderr, done.stderr
        assert "cannot be saved" in done.stderr, done.stderr
        # The controller killed and restarted: it reads no engaged state (none could be
        # written), cannot save one, and so starts stopped and says why.
        restart_controller(stack)
        after = len(cmds)
        wait_for(lambda: len(cmds) > after + 40, 30, "commands of the restarted controller")
        assert moving(cmds, engaged) == [], "the robot moved on a stop that could not be saved"
        last = statuses_of(statuses)[-1]
        assert last.state == "estop" and not last.estop_saved, last
        assert "NOT SAVED" in last.reason, last.reason
        wait_for(lambda: "NOT SAVED" in stack.log(), 10, "the supervisor's line to say so")
    # Once the folder can be written again, an explicit release frees the robot.
    done = estop_cli(stack, "release")
    assert done.returncode == 0, done.stderr
    released = len(cmds)
    wait_for(lambda: moving(cmds, released), 30, "motion after the release")
    assert stack.stop() == 0, stack.log()


def test_a_corrupt_state_is_engaged_never_a_crash(make_stack, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    # One corrupt state on real processes; the others (a stamp out of range ...) in-process:
    # tests/unit/controller/test_loop.py and test_estop.py.
    path = tmp_path / "estop.json"
    path.write_text('{"engaged": [], "since_ns": 0, "by": "x", "reason": "y"}')
    stack: Stack = make_stack(controller={"estop_file": str(path)})
    stack.wait_ready(STACK)
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, dets = stack.subscribe(stack.keys.detections("front"))
    wait_for(lambda: len(dets) > 10, 60, "detections of the cameraman (without a latch: motion)")
    assert moving(cmds) == [], "a corrupt e-stop state was read as released"
    assert "controller" in stack.ready_services()
    assert "restarted" not in stack.log(), "the controller crashed on its state file"
    assert json.loads(path.read_text())["engaged"] is True  # rewritten well-formed, engaged
    assert estop_cli(stack, "release").returncode == 0
    wait_for(lambda: moving(cmds), 30, "motion after an explicit release")
    assert stack.stop() == 0, stack.log()


def test_an_engage_stamped_a_century_ahead_can_be_released(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack()
    stack.wait_ready(STACK)
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, statuses = stack.subscribe(stack.keys.controller_status())
    wait_for(lambda: moving(cmds), 60, "motion towards the cameraman")
    rogue = stack.session.declare_publisher(stack.keys.estop())
    at = now()
    ahead = EStop(header=header(at.wall_ns + CENTURY_NS, source="far-future"), engaged=True,
                  reason="a century ahead")  # fmt: skip
    rogue.put(ahead.encode())
    wait_for(lambda: any(s.state == "estop" for s in statuses_of(statuses)), 10, "the latch")
    engaged = len(cmds)
    pause(1.0)
    assert moving(cmds, engaged) == []
    # The operator's release, stamped now, clears it: the latch kept the stop as of its own
    # clock, not a century ahead. The CLI's answer is true either way.
    done = estop_cli(stack, "release")
    assert done.returncode == 0 and done.stdout.strip() == "e-stop released", done.stderr
    wait_for(lambda: moving(cmds, engaged), 30, "motion after the release")
    # ... and a restarted controller does not bring the century back.
    restart_controller(stack)
    after = len(cmds)
    wait_for(lambda: moving(cmds, after), 30, "motion after the controller's restart")
    assert stack.stop() == 0, stack.log()


def test_an_engage_stops_at_once_not_at_the_next_control_tick(make_stack) -> None:  # type: ignore[no-untyped-def]
    # One control tick a second (the slowest rate allowed) and no detections to wake the loop
    # between ticks: a stop sent just after a tick must not wait for the next one.
    stack: Stack = make_stack(
        supervisor={"services": ["controller"]}, controller={"control_rate_hz": 1.0}
    )
    period_ns = 10**9
    stack.wait_ready({"controller"})
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, statuses = stack.subscribe(stack.keys.controller_status())
    wait_for(lambda: len(statuses) >= 2, 30, "two control ticks")
    ticked = len(statuses)
    wait_for(lambda: len(statuses) > ticked, 30, "a control tick")
    at = now()  # just after a tick: the next is about a second away
    engage = EStop(header=header(at.wall_ns, "test", at.mono_ns), engaged=True, reason="test")
    stack.session.put(stack.keys.estop(), engage.encode())
    [stopped, *_] = wait_for(
        lambda: [s for s in statuses_of(statuses) if s.state == "estop"], 30, "the e-stop status"
    )
    last_tick = max(
        s.header.stamp_ns for s in statuses_of(statuses) if s.header.stamp_ns <= at.wall_ns
    )
    # The next tick could not come before last_tick + period: well before it, the stop is out.
    soon = last_tick + period_ns // 2
    zeros = [t for t in map(Twist.decode, list(cmds)) if at.wall_ns <= t.header.stamp_ns < soon]
    assert zeros and all(t.is_zero for t in zeros), (
        f"no command within {(soon - at.wall_ns) / 1e9:.2f} s of the engage; the e-stop's "
        f"status came {(stopped.header.stamp_ns - last_tick) / 1e9:.2f} s after the last tick"
    )
    assert stopped.header.stamp_ns < soon, "the e-stop's status waited for the next tick"
    assert stack.stop() == 0, stack.log()


def test_a_release_is_acknowledged_at_once_not_at_the_next_control_tick(make_stack) -> None:  # type: ignore[no-untyped-def]
    # As above, one tick a second: the release's status (what the e-stop command waits for)
    # must not wait for the next tick either.
    stack: Stack = make_stack(
        supervisor={"services": ["controller"]}, controller={"control_rate_hz": 1.0}
    )
    stack.wait_ready({"controller"})
    _, statuses = stack.subscribe(stack.keys.controller_status())
    at = now()
    engage = EStop(header=header(at.wall_ns, "test", at.mono_ns), engaged=True, reason="test")
    stack.session.put(stack.keys.estop(), engage.encode())
    wait_for(lambda: any(s.state == "estop" for s in statuses_of(statuses)), 30, "the e-stop")
    ticked = len(statuses)
    wait_for(lambda: len(statuses) > ticked, 30, "a control tick")
    at = now()  # just after a tick: the next is about a second away
    release = EStop(header=header(at.wall_ns, "test", at.mono_ns), engaged=False, reason="test")
    stack.session.put(stack.keys.estop(), release.encode())
    [released, *_] = wait_for(
        lambda: [s for s in statuses_of(statuses)[ticked:] if s.state != "estop"], 30, "release"
    )
    last_tick = max(
        s.header.stamp_ns for s in statuses_of(statuses) if s.header.stamp_ns <= at.wall_ns
    )
    assert released.header.stamp_ns < last_tick + 10**9 // 2, (
        f"the release's status came {(released.header.stamp_ns - at.wall_ns) / 1e9:.2f} s after "
        "the release: it waited for the next tick"
    )
    assert stack.stop() == 0, stack.log()


def test_an_engage_on_the_controllers_host_stops_without_zenoh(make_stack, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    # The operator's command on the robot, with its Zenoh road cut (the config's endpoint
    # answers nothing): the controller takes the engage through its local socket all the same
    # (common/estop_local.py), and the command says that nothing confirmed it.
    stack: Stack = make_stack()
    stack.wait_ready(STACK)
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, statuses = stack.subscribe(stack.keys.controller_status())
    wait_for(lambda: moving(cmds), 60, "motion towards the cameraman")
    cut = tmp_path / "cut.toml"
    cut.write_text(
        f'extends = "{stack.config_path}"\n[zenoh]\nendpoint = "tcp/127.0.0.1:{free_port()}"\n'
    )
    done = subprocess.run(
        [sys.executable, "-m", "deploy.zstack", "estop", "engage", "--config", str(cut),
         "--reason", "ramp ahead"],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 1, done.stdout + done.stderr
    assert "took the engage through its local e-stop socket" in done.stderr, done.stderr
    [stopped, *_] = wait_for(
        lambda: [s for s in statuses_of(statuses) if s.state == "estop"], 30, "the e-stop status"
    )
    assert "estop-local: ramp ahead" in stopped.reason and stopped.estop_saved, stopped
    engaged = len(cmds)
    pause(1.0)
    assert moving(cmds, engaged) == [], "the robot moved after a local engage"
    # Only an engage comes this way: the release is the Zenoh road's, and it frees the robot.
    assert estop_cli(stack, "release").returncode == 0
    wait_for(lambda: moving(cmds, engaged), 30, "motion after the release")
    assert stack.stop() == 0, stack.log()
