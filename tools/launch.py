"""Running a stack from outside it: a private port, the supervisor as a child, readiness, a
clean stop, and the PIDs of the services it started.

Where a tool's private stacks listen: each on a port the system picks free, or, once a
command's ``--port N`` has called ``use_ports``, on N, N+1, ... in the order the tool
asks (tools/ports.py). Where their files go: a folder of the run's own in the
temporary folder (``$TMPDIR``, else ``/tmp``: :func:`run_folder`), which also holds their
controller's state files (:func:`private_state`), never the robot's own in ``state/``.

Every tool here writes the whole config it wants (the user's, with the user's environment
overrides already applied, plus its private port) and the supervisor reads only that file.

The scenario runner (``tools/scenarios/runner.py``), the report's recorder
(``tools/report/session.py``) and the integration tests start stacks this way. The
supervisor gets a process group of its own, so a Ctrl-C at the terminal reaches only the caller,
which then stops the stack with one SIGINT, as a person would. It stays in the caller's session,
as its services stay in its own: CPU priorities rank processes within a session only
(common/priority.py), and a benchmark's recorder must rank as the service would.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import IO

import zenoh

from common.bus import Bus
from common.clock import mono_s
from common.errors import ConfigError, StackError
from common.files import temp_root
from common.keys import Keys
from common.queries import ready_services
from common.settings import REPO_ROOT, service_package
from common.spawn import spawn, stop_child
from stack.config import Config
from stack.config_file import load_config, to_toml
from stack.config_read import ENV_PREFIX
from tools.ports import free_port as free_port  # the port plan's home is tools/ports.py


def run_folder(prefix: str) -> Path:
    """A fresh folder for one run's files (its configs, logs, state), kept after the run, in
    the temporary folder: ``$TMPDIR``, else ``/tmp`` (common/files.py ``temp_root``)."""
    return Path(tempfile.mkdtemp(prefix=prefix, dir=temp_root()))


def private_state(config: Config, folder: Path, name: str = "") -> Config:
    """``config`` with its controller's state files (the latched e-stop, the depth map) in
    ``folder`` (named ``<name>-...`` when given): a private stack starts afresh, and never
    reads, writes or leaves one beside a robot's own (``state/`` in the repo)."""
    lead = f"{name}-" if name else ""
    return dataclasses.replace(
        config,
        controller=dataclasses.replace(
            config.controller,
            estop_file=str(folder / f"{lead}estop.json"),
            depth_memory_file=str(folder / f"{lead}depth-memory.npz"),
        ),
    )


def start_supervisor(
    config_path: str | Path, log: IO[bytes], env: Mapping[str, str] | None = None
) -> subprocess.Popen[bytes]:
    """Start ``python -m deploy.supervisor --config config_path`` in a process group of its own
    (common/spawn.py), once the models its detector loads are prepared (:func:`prepare_models`).

    Its output (stdout and stderr, unbuffered) goes to ``log``; ``env`` replaces this process's
    environment when given. The file is the whole truth: ``STACK__*`` overrides are taken out
    of the supervisor's environment, so that an endpoint exported in the caller's shell cannot
    move a stack that a tool started on a private port (a caller folds the overrides it wants
    into the file it writes: :func:`write_config`).
    """
    base = os.environ if env is None else env
    clean = {k: v for k, v in base.items() if not k.startswith(ENV_PREFIX)}
    try:
        config = load_config(config_path, environ=clean)
    except ConfigError:
        config = None  # the supervisor says what is wrong with it, as it would unprepared
    if config is not None:
        prepare_models(config, log)
    return spawn(
        [sys.executable, "-m", "deploy.supervisor", "--config", str(config_path)],
        env=clean,
        cwd=REPO_ROOT,
        stdout=log,
        stderr=subprocess.STDOUT,
    )


def prepare_models(config: Config, log: IO[bytes]) -> None:
    """Prepare what ``config``'s detector loads, as ``zstack prepare`` does (the detector only
    loads): the model at another input size, INT8, the fast profile's choice once measured.
    Quick when it is all there already; progress lines go to ``log``. The fast profile is
    never measured here (minutes): unmeasured, NotPrepared says to run ``zstack prepare``."""
    if "detector" not in config.supervisor.services:
        return
    from perception import prepare_for

    def progress(line: str) -> None:
        log.write(f"prepare: {line}\n".encode())
        log.flush()

    prepare_for(config.detector, progress)


def write_config(config: Config, path: Path) -> Path:
    """Write ``config`` as it was loaded (the file and the environment's overrides together)
    to ``path``: what a tool hands the supervisor it starts."""
    path.write_text(to_toml(config))
    return path


def wait_ready(
    session: Bus | zenoh.Session,
    keys: Keys,
    services: set[str],
    proc: subprocess.Popen[bytes],
    timeout_s: float,
    *,
    stop: threading.Event | None = None,
    log_path: Path | None = None,
    poll_s: float = 0.2,
) -> None:
    """Wait until every one of ``services`` holds its health token.

    Raises StackError when the supervisor exits first or ``timeout_s`` passes (naming
    ``log_path`` when given), and KeyboardInterrupt when ``stop`` is set.
    """
    see = f"; see {log_path}" if log_path is not None else ""
    deadline = mono_s() + timeout_s
    pause = stop if stop is not None else threading.Event()  # never set: wait() is the poll
    while not services <= ready_services(session, keys):
        if proc.poll() is not None:
            raise StackError(f"the stack exited ({proc.returncode}) before it was ready{see}")
        if mono_s() > deadline:
            raise StackError(f"the stack was not ready within {timeout_s:.0f} s{see}")
        if pause.wait(poll_s):
            raise KeyboardInterrupt


def stop_supervisor(
    proc: subprocess.Popen[bytes], timeout_s: float, sig: int = signal.SIGINT
) -> bool:
    """Signal the supervisor (SIGINT, as Ctrl-C would) and wait ``timeout_s`` for it to exit.

    True when it exited in time (its code is then ``proc.returncode``); otherwise its whole
    process group is killed, and False is returned.
    """
    return stop_child(proc, timeout_s, sig, whole_group=True)


def service_pids(service: str, config_path: str | Path) -> list[int]:
    """PIDs of ``python -m services.<service> ... --config <config_path>`` (Linux /proc).

    A camera's process is found by its service name as the supervisor names it
    (deploy/processes.py): ``camera`` is the first camera's (started without ``--camera``),
    ``camera_<name>`` a further camera's (``--camera <name>``); likewise ``detector`` is the
    first detector worker's, ``detector_<n>`` a further one's (``--worker detector_<n>``).
    """
    package = service_package(service)
    further = package != service
    camera = service.removeprefix("camera_").encode() if further and package == "camera" else None
    worker = service.encode() if further and package == "detector" else None
    want = (f"services.{package}".encode(), str(config_path).encode())
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue  # the process ended while we looked
        if (
            all(w in argv for w in want)
            and _arg(argv, b"--camera") == camera
            and _arg(argv, b"--worker") == worker
        ):
            pids.append(int(entry.name))
    return pids


def _arg(argv: list[bytes], flag: bytes) -> bytes | None:
    """The value of ``flag`` in ``argv``, None without one."""
    for i, arg in enumerate(argv[:-1]):
        if arg == flag:
            return argv[i + 1]
    return None


def rss_kb(pid: int) -> int | None:
    """Process ``pid``'s resident memory (``VmRSS``, kB); None once it has gone."""
    return _proc_field(f"/proc/{pid}/status", "VmRSS:")


def pss_kb(pid: int) -> int | None:
    """Process ``pid``'s proportional set size (kB): its resident pages, each shared page
    divided by the number of processes mapping it, so that the sum over processes is the
    memory they take together (summed RSS counts a shared library once per process). None
    once it has gone (or where the kernel has no ``smaps_rollup``, before Linux 4.14)."""
    return _proc_field(f"/proc/{pid}/smaps_rollup", "Pss:")


def _proc_field(path: str, name: str) -> int | None:
    try:
        text = Path(path).read_text()
    except OSError:
        return None  # the process ended while we looked
    for line in text.splitlines():
        if line.startswith(name):
            return int(line.split()[1])
    return None
