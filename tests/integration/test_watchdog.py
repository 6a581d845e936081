"""A hung service: the supervisor's watchdog reports it, kills it and restarts it."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from common.messages import Detections
from tests.integration.conftest import Stack, wait_for
from tools.launch import service_pids

pytestmark = pytest.mark.integration


def test_a_frozen_detector_is_reported_killed_and_restarted(make_stack) -> None:  # type: ignore[no-untyped-def]
    # SIGSTOP freezes every thread: the work loop's heartbeat (its counters) stops at once, the
    # liveliness token only when Zenoh's lease runs out (about 10 s). Short timeouts keep it fast.
    stack: Stack = make_stack(
        supervisor={
            "services": ["camera", "detector"],
            "watchdog_progress_s": 2.0,
            "watchdog_grace_s": 1.0,
            "stop_timeout_s": 2.0,
        }
    )
    stack.wait_ready({"camera", "detector"})
    _, dets = stack.subscribe(stack.keys.detections("front"))
    wait_for(lambda: len(dets) >= 2, 60, "detections before the freeze")
    [pid] = service_pids("detector", stack.config_path)
    os.kill(pid, signal.SIGSTOP)

    wait_for(lambda: "detector: hung (" in stack.log(), 20, lambda: f"a report:\n{stack.log()}")
    report = next(line for line in stack.log().splitlines() if "detector: hung (" in line)
    assert "its work loop has published no counters for" in report
    wait_for(
        lambda: [p for p in service_pids("detector", stack.config_path) if p != pid],
        30,
        "the supervisor to restart the detector",
    )
    assert not Path(f"/proc/{pid}").exists(), "the frozen detector was left behind"
    n_dets = len(dets)
    wait_for(lambda: len(dets) > n_dets + 2, 120, "detections to resume after the restart")
    assert Detections.decode(dets[-1]).class_names, "the restarted detector finds nothing"
    wait_for(
        lambda: "detector:ready(r1, 1 hung)" in stack.log(),
        10,
        lambda: f"the status line to show the restart:\n{stack.log()}",
    )
    assert stack.stop() == 0, stack.log()
