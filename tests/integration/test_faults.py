"""A dead detector: the controller stops, the supervisor restarts it, detections resume."""

from __future__ import annotations

import os
import signal

import pytest

from common.messages import ControllerStatus, Detections, Twist
from tests.integration.conftest import Stack, wait_for
from tools.launch import service_pids

pytestmark = pytest.mark.integration


def test_killed_detector_stops_robot_and_is_restarted(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(controller={"detection_timeout_s": 0.5})
    stack.wait_ready({"camera", "detector", "controller", "metrics"})
    _, dets = stack.subscribe(stack.keys.detections("front"))
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, statuses = stack.subscribe(stack.keys.controller_status())
    wait_for(
        lambda: any(not Twist.decode(c).is_zero for c in list(cmds)),
        60,
        "a non-zero command while the cameraman is tracked",
    )

    [pid] = service_pids("detector", stack.config_path)
    os.kill(pid, signal.SIGKILL)
    killed_at = len(cmds)

    def zero_after_timeout() -> bool:
        after = [ControllerStatus.decode(s) for s in list(statuses)[killed_at:]]
        return any(s.state == "stale" for s in after)

    wait_for(zero_after_timeout, 5.0, "the controller to go stale after the detector died")
    n_dets = len(dets)
    wait_for(
        lambda: [p for p in service_pids("detector", stack.config_path) if p != pid],
        30,
        "the supervisor to restart the detector",
    )
    wait_for(lambda: len(dets) > n_dets + 2, 120, "detections to resume after the restart")
    assert Detections.decode(dets[-1]).class_names, "the restarted detector finds nothing"
    # Every command sent while the controller reported stale inputs was zero. A status and
    # its command share one header, so the sequence number pairs them.
    stale_seqs = {
        st.header.seq for st in map(ControllerStatus.decode, list(statuses)) if st.state == "stale"
    }
    stale_cmds = [t for t in map(Twist.decode, list(cmds)) if t.header.seq in stale_seqs]
    assert stale_cmds, "no command was seen while stale"
    assert all(t.is_zero for t in stale_cmds)
    assert stack.stop() == 0, stack.log()
    assert "detector: exited with code" in stack.log()


def test_estop_latches_zero_until_released(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack()
    stack.wait_ready({"camera", "detector", "controller"})
    _, cmds = stack.subscribe(stack.keys.cmd_vel())
    _, statuses = stack.subscribe(stack.keys.controller_status())
    wait_for(lambda: any(not Twist.decode(c).is_zero for c in list(cmds)), 60, "motion")

    stack.estop("engage")
    engaged_at = len(statuses)
    # Let several control ticks pass; every one of them must be a latched zero.
    wait_for(lambda: len(statuses) > engaged_at + 20, 10, "control ticks while e-stopped")
    latched = [ControllerStatus.decode(s) for s in list(statuses)[engaged_at + 2 :]]
    seqs = {st.header.seq for st in latched}
    assert all(st.state == "estop" for st in latched)
    assert all(t.is_zero for t in map(Twist.decode, list(cmds)) if t.header.seq in seqs)
    stack.estop("release")
    released_at = len(cmds)
    wait_for(
        lambda: any(not Twist.decode(c).is_zero for c in list(cmds)[released_at:]),
        30,
        "motion after the release",
    )
    assert stack.stop() == 0, stack.log()
