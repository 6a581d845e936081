from __future__ import annotations

import os
import signal
import sys
import threading
import time

import pytest

from deploy.processes import Backoff, ServiceProcess
from stack.config import SupervisorSettings


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


def _wait_ignoring(pid: int, sig: int = signal.SIGINT) -> None:
    """Wait until the child has installed its ignore handler for ``sig`` (Linux /proc)."""
    deadline, pause = time.monotonic() + 10, threading.Event()
    while time.monotonic() < deadline:
        with open(f"/proc/{pid}/status") as f:
            ignored = next(int(line.split()[1], 16) for line in f if line.startswith("SigIgn"))
        if ignored & (1 << (sig - 1)):
            return
        pause.wait(0.01)
    pytest.fail(f"the child never ignored signal {sig}")


def test_stop_escalates_to_kill() -> None:
    code = "import signal; signal.signal(signal.SIGINT, signal.SIG_IGN); signal.pause()"
    proc = ServiceProcess("stubborn", [sys.executable, "-c", code], SETTINGS)
    proc.start()
    assert proc.proc is not None
    _wait_ignoring(proc.proc.pid)
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


def test_a_hung_process_is_killed_even_when_stopped_and_restarted_with_backoff() -> None:
    # Stubborn: ignores SIGTERM, and is frozen (SIGSTOP) like a hung service seen by the
    # watchdog. The supervisor must still get rid of it, then restart it as after a crash.
    code = "import signal; signal.signal(signal.SIGTERM, signal.SIG_IGN); signal.pause()"
    settings = SupervisorSettings(
        restart_backoff_s=0.05, restart_backoff_max_s=1.0, stop_timeout_s=0.3
    )
    proc = ServiceProcess("frozen", [sys.executable, "-c", code], settings)
    proc.start()
    assert proc.proc is not None
    first = proc.proc
    _wait_ignoring(first.pid, signal.SIGTERM)
    proc.mark_ready(time.monotonic())
    os.kill(first.pid, signal.SIGSTOP)
    line = proc.hung("its work loop has published no counters for 3.0 s", time.monotonic())
    assert line.startswith("frozen: hung (its work loop") and proc.state == "hung"
    events = _poll_until(proc, "backoff")
    assert any("after SIGTERM; killed" in e for e in events), events
    assert "after it hung; restarting in" in events[-1]
    assert proc.backoff.current_s == pytest.approx(0.05)  # the first delay, as after a crash
    assert first.returncode == -signal.SIGKILL
    _poll_until(proc, "starting")
    assert proc.restarts == 1 and proc.hangs == 1 and proc.proc is not first
    proc.signal_stop()
    proc.wait_stopped(time.monotonic() + 1)
