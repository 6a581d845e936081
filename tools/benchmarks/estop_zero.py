"""python -m tools.benchmarks estop --to-zero: from ``zstack estop engage``'s start to the
controller's stop, on a real controller, this checkout's command against another revision's,
side by side, with CPU burners beside them.

A supervisor runs this checkout's controller alone (no detections: it commands zero at its
rate, and an engage is seen by its ``estop`` status, which it sends as soon as its zero is
out). ``--burners N`` busy loops (``while True: pass``) run beside it, each in a session of
its own as from another terminal, so that every core is busy. Each run starts the command as
an operator would, from the revision's folder (this checkout, or a ``git archive`` of the
other revision), and times from just before the process starts to the arrival of the
controller's first ``estop`` status on this process's monotonic clock; the e-stop is then
released over Zenoh and the controller's release awaited before the next run. The two
revisions alternate run by run, so that both see the same load. Both read the same config,
the controller's own: this checkout's command may hand the engage to the controller through
its local socket (common/estop_local.py); an older one has only Zenoh.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import zenoh

from common.clock import BOOT_ID, mono_s, now
from common.contracts import ControllerState
from common.control_messages import ControllerStatus, EStop, Header
from common.errors import DecodeError
from common.files import temp_root
from common.keys import Keys
from common.machine import machine_info
from common.settings import REPO_ROOT
from common.spawn import spawn
from common.zenoh_bus import open_session
from stack.config_file import load_config
from tools.benchmarks.estop import THIS, EstopOptions, _export, _runs_from, show, tally
from tools.launch import start_supervisor
from tools.ports import private_endpoint

#: The longest a run waits for the controller's stop (or, after it, its release).
STOP_TIMEOUT_S = 30.0
#: The longest the controller is given to start and send its first status.
START_TIMEOUT_S = 120.0
BURN = "while True: pass"


class Statuses:
    """The controller's status as it arrives: whether it is stopped by the e-stop now, and
    when that was first seen after :meth:`expect` set which state is awaited."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._want: bool | None = None
        self._seen_at = 0.0
        self.changed = threading.Event()
        self.heard = threading.Event()

    def expect(self, engaged: bool) -> None:
        with self._lock:
            self._want, self._seen_at = engaged, 0.0
            self.changed.clear()

    def on_status(self, sample: zenoh.Sample) -> None:
        at = mono_s()
        try:
            status = ControllerStatus.decode(sample.payload.to_bytes())
        except DecodeError:
            return
        self.heard.set()
        with self._lock:
            if self._want is None or self.changed.is_set():
                return
            if (status.state == ControllerState.ESTOP) == self._want:
                self._seen_at = at
                self.changed.set()

    def seen_at(self) -> float:
        with self._lock:
            return self._seen_at


def _config(folder: Path) -> Path:
    path = folder / "stack.toml"
    path.write_text(
        f'[zenoh]\nendpoint = "{private_endpoint()}"\nmulticast_scouting = false\n'
        f'[stack]\nprefix = "estopzero"\n'
        f'[supervisor]\nservices = ["controller"]\n'
        f'[controller]\nestop_file = "{folder / "state" / "estop.json"}"\n'
        'no_laser = true\nmode = "track"\n'
        f'depth_memory_file = "{folder / "state" / "depth.npz"}"\n'
    )
    return path


@contextlib.contextmanager
def _burners(count: int) -> Iterator[None]:
    procs = [spawn([sys.executable, "-c", BURN], new_session=True) for _ in range(count)]
    try:
        yield
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()


def _release(pub: zenoh.Publisher) -> None:
    at = now()
    header = Header(
        stamp_ns=at.wall_ns, frame_id="", seq=0, source="estop-bench", mono_ns=at.mono_ns,
        boot_id=BOOT_ID,
    )  # fmt: skip
    pub.put(EStop(header=header, engaged=False, reason="benchmark").encode())


def _one(cwd: Path, config: Path, statuses: Statuses) -> float | None:
    """One engage from ``cwd``'s command: seconds to the controller's stop, None if none."""
    statuses.expect(True)
    start = mono_s()
    proc = spawn(
        [sys.executable, "-m", "deploy.zstack", "estop", "engage", "--config", str(config),
         "--reason", "benchmark"],
        cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    stopped = statuses.changed.wait(STOP_TIMEOUT_S)
    try:
        proc.wait(STOP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    return statuses.seen_at() - start if stopped else None


def run_to_zero(options: EstopOptions) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="estop-zero-", dir=temp_root()) as tmp:
        folder = Path(tmp)
        old = folder / "old"
        commit = _export(options.against, old)
        if not _runs_from(old):
            raise SystemExit(f"estop benchmark: {options.against} would not run from {old}")
        config_path = _config(folder)
        config = load_config(config_path, environ={})
        keys = Keys(config.stack.prefix)
        statuses = Statuses()
        times: dict[str, list[float]] = {THIS: [], options.against: []}
        lost = dict.fromkeys(times, 0)
        loads: list[float] = []
        with (folder / "supervisor.log").open("wb") as log:
            supervisor = start_supervisor(config_path, log)
            session = open_session(config.zenoh, config.principal("observer"))
            try:
                sub = session.declare_subscriber(keys.controller_status(), statuses.on_status)
                pub = session.declare_publisher(keys.estop())
                if not statuses.heard.wait(START_TIMEOUT_S):
                    raise SystemExit("estop benchmark: the controller never sent a status")
                with _burners(options.burners):
                    for i in range(options.runs):
                        order = [(THIS, REPO_ROOT), (options.against, old)]
                        for name, cwd in order if i % 2 == 0 else order[::-1]:
                            took = _one(cwd, config_path, statuses)
                            if took is None:
                                lost[name] += 1
                            else:
                                times[name].append(took)
                            statuses.expect(False)
                            _release(pub)
                            if not statuses.changed.wait(STOP_TIMEOUT_S):
                                raise SystemExit("estop benchmark: the release was not taken")
                        loads.append(os.getloadavg()[0])
                        print(
                            f"estop benchmark: {i + 1}/{options.runs}", file=sys.stderr, flush=True
                        )
                sub.undeclare()
            finally:
                session.close()
                supervisor.terminate()
                supervisor.wait(60)
    report, ratio = tally(times, lost, options.against)
    return {
        "runs": options.runs,
        "burners": options.burners,
        "against": {"revision": options.against, "commit": commit},
        "to_the_stop": report,
        "p50_ratio": None if ratio is None else round(ratio, 2),
        "load_average": [round(min(loads), 1), round(max(loads), 1)] if loads else [],
        "machine": machine_info(),
    }


def main(options: EstopOptions) -> int:
    return show(run_to_zero(options), options, "the controller's stop", "to_the_stop")
