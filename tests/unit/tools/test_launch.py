"""Launch helpers: a free port, readiness with a deadline, a stop that escalates to a kill."""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from common.errors import ConfigError, StackError
from common.keys import Keys
from common.memory_bus import MemoryBus, MemoryHub
from services.controller.contract import ControllerSettings
from stack.config import Config
from tools.launch import (
    free_port,
    private_state,
    run_folder,
    service_pids,
    stop_supervisor,
    wait_ready,
)

KEYS = Keys("test")


def ready_bus(*ready: str) -> MemoryBus:
    """An in-memory bus on which ``ready`` services hold their health tokens."""
    hub = MemoryHub()
    for name in ready:
        hub.join(name).declare_token(KEYS.health(name))
    return hub.join("launcher")


def _child(code: str) -> subprocess.Popen[str]:
    """A child in a session of its own (as the supervisor runs) that prints a line when set."""
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, start_new_session=True
    )
    assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
    return proc


@pytest.fixture
def sleeper() -> Iterator[subprocess.Popen[str]]:
    proc = _child("import signal; print('ready', flush=True); signal.pause()")
    yield proc
    proc.kill()
    proc.wait()


def test_free_port_can_be_bound() -> None:
    port = free_port()
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))


def test_wait_ready_returns_once_every_service_is_ready(sleeper: Any) -> None:
    wait_ready(ready_bus("detector", "camera"), KEYS, {"camera"}, sleeper, timeout_s=5)


def test_wait_ready_gives_up_at_the_deadline_naming_the_log(sleeper: Any) -> None:
    with pytest.raises(StackError, match=r"not ready within 0 s; see /tmp/stack\.log"):
        wait_ready(
            ready_bus("camera"), KEYS, {"detector"}, sleeper, 0.0, log_path=Path("/tmp/stack.log")
        )


def test_wait_ready_stops_when_the_stack_exits() -> None:
    proc = subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
    proc.wait()
    with pytest.raises(StackError, match=r"exited \(3\) before it was ready"):
        wait_ready(ready_bus(), KEYS, {"detector"}, proc, timeout_s=5)


def test_wait_ready_is_interrupted_by_the_stop_event(sleeper: Any) -> None:
    stop = threading.Event()
    stop.set()
    with pytest.raises(KeyboardInterrupt):
        wait_ready(ready_bus(), KEYS, {"detector"}, sleeper, 5, stop=stop)


def test_stop_supervisor_sends_sigint_and_returns_the_exit_code() -> None:
    proc = _child(
        "import signal, sys\n"
        "signal.signal(signal.SIGINT, lambda *_: sys.exit(0))\n"
        "print('ready', flush=True)\n"
        "signal.pause()"
    )
    assert stop_supervisor(proc, timeout_s=10) is True
    assert proc.returncode == 0


def test_stop_supervisor_kills_what_ignores_sigint_after_the_deadline() -> None:
    proc = _child(
        "import signal\n"
        "signal.signal(signal.SIGINT, signal.SIG_IGN)\n"
        "print('ready', flush=True)\n"
        "signal.pause()"
    )
    assert stop_supervisor(proc, timeout_s=0.3) is False
    assert proc.returncode == -9


def test_service_pids_tells_each_camera_process_by_its_service_name(tmp_path: Path) -> None:
    # Stand-ins with the argv the supervisor gives camera processes (deploy/processes.py).
    config = str(tmp_path / "stack.toml")
    code = "import signal; print('ready', flush=True); signal.pause()"
    argv = {
        "camera": ["services.camera", "serve", "--config", config],
        "camera_rear": ["services.camera", "serve", "--config", config, "--camera", "rear"],
        "camera_left": ["services.camera", "serve", "--config", config, "--camera", "left"],
        "detector": ["services.detector", "serve", "--config", config],
    }
    procs = {}
    for name, args in argv.items():
        proc = subprocess.Popen(
            [sys.executable, "-c", code, *args], stdout=subprocess.PIPE, text=True
        )
        assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
        procs[name] = proc
    try:
        for name, proc in procs.items():
            assert service_pids(name, config) == [proc.pid], name
        assert service_pids("camera_back", config) == []
        assert service_pids("camera", str(tmp_path / "other.toml")) == []
    finally:
        for proc in procs.values():
            proc.kill()
            proc.wait()


def test_rss_kb_reads_a_live_process_and_none_once_gone() -> None:
    import os

    from tools.launch import rss_kb

    own = rss_kb(os.getpid())
    assert own is not None and own > 1000  # a Python process is megabytes
    assert rss_kb(0) is None  # no /proc/0: as a process that has ended


def test_pss_kb_is_at_most_rss_and_none_once_gone() -> None:
    import os

    from tools.launch import pss_kb, rss_kb

    pss, rss = pss_kb(os.getpid()), rss_kb(os.getpid())
    assert pss is not None and rss is not None
    assert 1000 < pss <= rss * 1.05  # shared pages count in part; allow pages mapped between reads
    assert pss_kb(0) is None


def test_a_run_folder_is_made_in_tmpdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    folder = run_folder("scenario-ahead-")
    assert folder.parent == tmp_path and folder.name.startswith("scenario-ahead-")
    # A TMPDIR that cannot hold it is named, not passed over for /tmp without a word.
    monkeypatch.setenv("TMPDIR", str(tmp_path / "missing"))
    with pytest.raises(ConfigError, match=r"TMPDIR=.*missing is not a folder"):
        run_folder("scenario-ahead-")


def test_a_private_stack_keeps_its_controller_state_in_its_own_folder(tmp_path: Path) -> None:
    # Never the robot's own state/estop-<prefix>.json in the repo, nor a path of the user's
    # config (a scenario run must not read, or release, a real robot's latched e-stop).
    mine = Config(controller=ControllerSettings(estop_file="/var/lib/robot/estop.json"))
    config = private_state(mine, tmp_path, "robot1")
    assert config.estop_path == tmp_path / "robot1-estop.json"
    assert config.depth_memory_path == tmp_path / "robot1-depth-memory.npz"
    assert private_state(Config(), tmp_path).estop_path == tmp_path / "estop.json"
