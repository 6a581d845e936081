from __future__ import annotations

import sys
import threading
import time

import pytest

from common.settings import SupervisorSettings
from deploy.processes import Backoff, ServiceProcess


def test_backoff_doubles_and_caps_and_resets() -> None:
    b = Backoff(initial_s=0.5, max_s=4.0)
    assert [b.next_delay(0.1) for _ in range(5)] == [0.5, 1.0, 2.0, 4.0, 4.0]
    assert b.next_delay(ran_for_s=10.0) == 0.5  # a long healthy run forgives earlier crashes


def _poll_until(proc: ServiceProcess, state: str, timeout: float = 10.0) -> list[str]:
    events, pause = [], threading.Event()
    deadline = time.monotonic() + timeout
    while proc.state != state:
        assert time.monotonic() < deadline, f"still {proc.state}, wanted {state}: {events}"
        if event := proc.poll(time.monotonic()):
            events.append(event)
        pause.wait(0.02)
    return events


SETTINGS = SupervisorSettings(restart_backoff_s=0.05, restart_backoff_max_s=1.0)


def test_crashing_process_is_restarted_with_backoff() -> None:
    proc = ServiceProcess("crasher", [sys.executable, "-c", "raise SystemExit(1)"], SETTINGS)
    proc.start()
    events = _poll_until(proc, "backoff")
    assert "exited with code 1" in events[-1]
    _poll_until(proc, "starting")
    assert proc.restarts == 1
    _poll_until(proc, "backoff")
    assert proc.backoff.current_s == pytest.approx(0.1)
    proc.wait_stopped(time.monotonic() + 1)


@pytest.mark.parametrize("code", [2, 3, 4])
def test_config_model_and_backend_errors_are_not_restarted(code: int) -> None:
    proc = ServiceProcess("bad", [sys.executable, "-c", f"raise SystemExit({code})"], SETTINGS)
    proc.start()
    events = _poll_until(proc, "failed")
    assert "no restart" in events[-1] and proc.restarts == 0


def _wait_ignoring_sigint(pid: int) -> None:
    """Wait until the child has installed its SIGINT-ignore handler (Linux /proc)."""
    deadline, pause = time.monotonic() + 10, threading.Event()
    while time.monotonic() < deadline:
        with open(f"/proc/{pid}/status") as f:
            ignored = next(int(line.split()[1], 16) for line in f if line.startswith("SigIgn"))
        if ignored & (1 << (2 - 1)):  # bit of signal 2 (SIGINT)
            return
        pause.wait(0.01)
    pytest.fail("the child never ignored SIGINT")


def test_stop_escalates_to_kill() -> None:
    code = "import signal; signal.signal(signal.SIGINT, signal.SIG_IGN); signal.pause()"
    proc = ServiceProcess("stubborn", [sys.executable, "-c", code], SETTINGS)
    proc.start()
    assert proc.proc is not None
    _wait_ignoring_sigint(proc.proc.pid)
    time_started = time.monotonic()
    proc.signal_stop()
    proc.wait_stopped(time.monotonic() + 0.5)
    assert proc.state == "exited" and proc.last_exit is not None and proc.last_exit < 0
    assert time.monotonic() - time_started < 5


def test_a_clean_exit_is_not_restarted() -> None:
    proc = ServiceProcess("done", [sys.executable, "-c", "raise SystemExit(0)"], SETTINGS)
    proc.start()
    events = _poll_until(proc, "exited")
    assert "not restarting" in events[-1] and proc.restarts == 0
