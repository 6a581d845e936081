"""Child processes of the supervisor: how each service is started, watched and restarted."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass, field
from typing import IO

from common.clock import mono_s
from common.lifecycle import PERMANENT_FAILURES, SUPERVISOR_PID_ENV
from common.priority import leave_idle, process_threads
from common.spawn import ask_to_stop, spawn, wait_or_kill
from stack.config import Config, SupervisorSettings


def service_command(name: str, config_path: str, camera: str = "", worker: str = "") -> list[str]:
    """Every service starts the same way (common/cli.py); a further camera's with
    ``--camera <name>`` (the first camera's without, as a one-camera stack always started it),
    a detector worker other than ``detector`` with ``--worker <its name>`` (``detector_2``,
    ``detector_gpu`` ...)."""
    command = [sys.executable, "-m", f"services.{name}", "serve", "--config", config_path]
    if camera:
        command += ["--camera", camera]
    if worker:
        command += ["--worker", worker]
    return command


def stack_processes(config: Config) -> list[tuple[str, list[str]]]:
    """(process name, command) of every process the supervisor runs, in start order: one per
    service of ``supervisor.services``, and for ``camera`` one per configured camera, each
    named as its service (``camera``, ``camera_<name>``: common/settings.py::camera_service),
    so that each has its own status, restarts, backoff and watchdog; likewise for
    ``detector`` one per worker of ``detector.workers`` (``detector``, ``detector_<n>``, or
    ``detector_<worker_id>`` ...: common/settings.py::detector_service)."""
    out = []
    for name in config.supervisor.services:
        if name == "detector":
            for service in config.detector_services:
                further = service if service != "detector" else ""
                out.append((service, service_command("detector", config.path, worker=further)))
            continue
        if name != "camera":
            out.append((name, service_command(name, config.path)))
            continue
        for camera, service in config.camera_services.items():
            further = camera if camera != config.stack.camera else ""
            out.append((service, service_command("camera", config.path, further)))
    return out


@dataclass
class Backoff:
    """Exponential restart delay: doubles on each crash, resets after a long enough run."""

    initial_s: float
    max_s: float
    current_s: float = 0.0

    def next_delay(self, ran_for_s: float) -> float:
        if ran_for_s >= self.max_s or self.current_s == 0.0:
            self.current_s = self.initial_s
        else:
            self.current_s = min(self.current_s * 2, self.max_s)
        return self.current_s


@dataclass
class ServiceProcess:
    """One service: its process, state, restart count and backoff."""

    name: str
    command: list[str]
    settings: SupervisorSettings
    proc: subprocess.Popen[bytes] | None = None
    state: str = "stopped"  # starting | ready | hung | backoff | failed | exited
    restarts: int = 0
    hangs: int = 0  # how many times the watchdog found it hung (deploy/watchdog.py)
    last_exit: int | None = None
    started_at: float = 0.0
    ready_at: float = 0.0
    restart_at: float = 0.0
    kill_at: float = 0.0  # while hung: when SIGKILL follows the SIGTERM
    last_error: str = ""  # the service's own one-line error, as it printed it
    backoff: Backoff = field(init=False)
    _forwarder: threading.Thread = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.backoff = Backoff(self.settings.restart_backoff_s, self.settings.restart_backoff_max_s)

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc else None

    def start(self) -> None:
        # The PID tells the service whom it must not outlive (common/lifecycle.py).
        env = {**os.environ, SUPERVISOR_PID_ENV: str(os.getpid())}
        # A process group of its own in our session (common/spawn.py: a Ctrl-C reaches the
        # supervisor only, which then stops the services in order; CPU priorities rank them
        # within our session). Its stdout goes to our stderr: our stdout carries only the
        # --duration summary. It starts with the stop signals blocked: a stop sent while its
        # interpreter starts stays pending until services/__init__.py can take it quietly.
        self.proc = spawn(
            self.command,
            env=env,
            stdout=sys.stderr.fileno(),
            stderr=subprocess.PIPE,
            stop_signals_blocked=True,
        )
        self.started_at = mono_s()
        self.state = "starting"
        assert self.proc.stderr is not None
        self._forwarder = threading.Thread(
            target=self._forward, args=(self.proc.stderr,), name=f"{self.name}-stderr", daemon=True
        )
        self._forwarder.start()

    def _forward(self, stream: IO[bytes]) -> None:
        """Pass the service's stderr through, remembering its one-line error if it prints one."""
        for line in stream:
            text = line.decode(errors="replace").strip()
            if text.startswith(("error: ", f"{self.name}: error: ")):
                named = text if text.startswith(self.name) else f"{self.name}: {text}"
                self.last_error = named
            sys.stderr.buffer.write(line)
            sys.stderr.buffer.flush()
        stream.close()

    def mark_ready(self, now: float) -> None:
        self.state, self.ready_at = "ready", now

    def hung(self, why: str, now: float) -> str:
        """The watchdog's verdict: stop the process (SIGTERM; SIGCONT, since a stopped process
        acts on no signal but SIGKILL), SIGKILL it at ``stop_timeout_s`` if it is still there;
        ``poll`` restarts it with the backoff of a crash. Returns the log line."""
        self.hangs += 1
        self.state, self.kill_at = "hung", now + self.settings.stop_timeout_s
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            self.proc.send_signal(signal.SIGCONT)
        return f"{self.name}: hung ({why}); killing it and restarting"

    def poll(self, now: float) -> str | None:
        """Check the process; on an exit, schedule the restart and return a log line."""
        if self.state == "backoff" and now >= self.restart_at:
            self.restarts += 1
            self.start()
            return f"{self.name}: restarted (restart #{self.restarts})"
        if self.proc is None or self.state in ("backoff", "failed", "exited"):
            return None
        code = self.proc.poll()
        if code is None:
            if self.state == "hung" and now >= self.kill_at:
                self.proc.kill()
                self.kill_at = math.inf  # once
                waited = self.settings.stop_timeout_s
                return f"{self.name}: still running {waited:g} s after SIGTERM; killed"
            return None
        self.last_exit = code
        if self.state == "hung":
            # Whatever it exited with, it was stopped for being hung: restart it.
            delay = self.backoff.next_delay(now - self.started_at)
            self.state, self.restart_at = "backoff", now + delay
            return (
                f"{self.name}: ended (exit code {code}) after it hung; restarting in {delay:.1f} s"
            )
        if code == 0:
            # It finished on purpose (a video that ended with loop = false): leave it be.
            self.state = "exited"
            return f"{self.name}: finished (exit code 0); not restarting"
        if code in PERMANENT_FAILURES:
            self.state = "failed"
            self._forwarder.join(timeout=2.0)  # its last words carry the reason
            return f"{self.name}: exited with code {code} (config, model or backend); no restart"
        delay = self.backoff.next_delay(now - self.started_at)
        self.state, self.restart_at = "backoff", now + delay
        return f"{self.name}: exited with code {code}; restarting in {delay:.1f} s"

    def signal_stop(self) -> None:
        if self.proc is not None:
            # A service in the idle CPU class (the recorder) gets no CPU at all while every
            # core is busy: not even to act on the stop. Out of it first, every thread, so
            # that it ends within stop_timeout_s however busy the cores.
            leave_idle(*process_threads(self.proc.pid))
            ask_to_stop(self.proc)

    def wait_stopped(self, deadline: float) -> None:
        """Wait for the process to exit by ``deadline``, then kill it."""
        if self.proc is None:
            self.state = "exited"
            return
        wait_or_kill(self.proc, deadline - mono_s())
        self.last_exit = self.proc.returncode
        self.state = "exited"
        self._forwarder.join(timeout=1.0)  # pass on its last words before we exit
