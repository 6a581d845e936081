"""Absurd settings stop a service with one line, and the supervisor does not restart it; the
controller at its slowest allowed rate still stops at once on SIGTERM (issue 13)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from deploy.processes import ServiceProcess
from stack.config import SupervisorSettings
from tests.integration.conftest import REPO, wait_for, write_config

pytestmark = pytest.mark.integration

RAYS = "STACK__SIM__LASER_RAYS"
LINE = f"{RAYS}: sim.laser_rays must be within 2..10000, got 200000"


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("STACK__")}
    return {**env, **extra}


def test_an_absurd_ray_count_is_one_line_and_a_permanent_failure(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    """It used to pass the checks, then crash the simulator with a traceback, again and
    again: the supervisor restarted it forever."""
    config = write_config(tmp_path, supervisor={"services": ["sim"]})
    # The service as the supervisor runs it: its process layer, with the override in the
    # environment it hands down.
    monkeypatch.chdir(REPO)
    monkeypatch.setenv(RAYS, "200000")
    sim = ServiceProcess(
        "sim",
        [sys.executable, "-m", "services.sim", "serve", "--config", str(config)],
        SupervisorSettings(restart_backoff_s=0.05),
    )
    sim.start()
    wait_for(
        lambda: sim.poll(time.monotonic()) or sim.state in ("failed", "backoff"),
        60,
        "the simulator to exit",
    )
    assert (sim.state, sim.last_exit, sim.restarts) == ("failed", 2, 0)
    assert sim.last_error == f"sim: error: {LINE}"
    err = capfd.readouterr().err
    assert "Traceback" not in err and err.strip() == f"sim: error: {LINE}", err
    # The supervisor itself reads the same config first: one line, exit 2, nothing started.
    done = subprocess.run(
        [sys.executable, "-m", "deploy.supervisor", "--config", str(config)],
        cwd=REPO, env=_env(**{RAYS: "200000"}), capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert (done.returncode, done.stderr.strip()) == (2, f"supervisor: error: {LINE}")


def test_the_controller_at_its_slowest_rate_stops_at_once_on_sigterm(tmp_path: Path) -> None:
    """A control period of 1/rate once held back SIGTERM (at 1e-9 Hz, for ever)."""
    config = write_config(tmp_path, controller={"control_rate_hz": 1.0})
    proc = subprocess.Popen(
        [sys.executable, "-m", "services.controller", "serve", "--config", str(config)],
        cwd=REPO, env=_env(), stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    lines: list[str] = []

    def read() -> None:
        for line in proc.stderr or ():
            lines.append(line)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        wait_for(lambda: any(" ready " in line for line in lines), 60, lambda: "".join(lines))
        start = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(timeout=30)
        took = time.monotonic() - start
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    reader.join(timeout=5)
    assert code == 0, "".join(lines)
    assert took < 2.0, f"SIGTERM took {took:.2f} s"
