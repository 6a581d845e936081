"""Fixtures that run the real stack: a private Zenoh endpoint, real processes, real model."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh

from common.announce import to_chunk
from common.boxes import Boxes
from common.errors import ConfigError, StackError
from common.frames import image_to_frame
from common.keys import Keys
from common.messages import Detections, Header
from common.queries import query_metrics, ready_services
from common.security import PRINCIPALS
from common.settings import principal_name
from common.zenoh_bus import open_session
from stack.config_file import load_config
from tests.polling import wait_for
from tests.unit.announced import announcement
from tools.launch import free_port, start_supervisor, stop_supervisor, wait_ready

REPO = Path(__file__).resolve().parents[2]
STARTUP_S = 120.0  # model load and warm-up on a loaded 2-core CI machine


def run_detector_cli(*args: str | Path, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    """The detector's command line as a user runs it: ``serve`` is the detector service's,
    every other command the detector tool's."""
    module = "services.detector" if args[0] == "serve" else "tools.detector"
    return subprocess.run(
        [sys.executable, "-m", module, *map(str, args)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def credentials_for(
    creds: Path, roles: Iterable[str] = PRINCIPALS, pool: str = "", **options: Any
) -> str:
    """``deploy.credentials.generate`` for the ``roles`` of a new test stack: each named as
    that stack's (common/security.py: ``<prefix>/<role>``, a worker ``<pool or prefix>/<role>``).
    Returns the prefix to give the stack (``stack.prefix``)."""
    from deploy.credentials import generate

    prefix = f"test/{uuid.uuid4().hex[:8]}"
    generate(creds, principals=tuple(principal_name(prefix, r, pool) for r in roles), **options)
    return prefix


def write_config(tmp: Path, **tables: dict[str, Any]) -> Path:
    """A stack config on a free port, with a unique key prefix, multicast off."""
    base: dict[str, dict[str, Any]] = {
        "zenoh": {"endpoint": f"tcp/127.0.0.1:{free_port()}", "multicast_scouting": False},
        "stack": {"prefix": f"test/{uuid.uuid4().hex[:8]}", "camera": "front"},
        "camera": {"source": "sample:cameraman", "rate_hz": 5.0},
        # A camera robot's services (the code's default, as deploy/stack.toml's, is the
        # simulator's stack); a test names its own.
        "supervisor": {
            "services": ["camera", "detector", "controller", "metrics"],
            "status_period_s": 1.0,
            "restart_backoff_s": 0.2,
        },
        # Each test's e-stop state of its own: a latched stop must not leak into the next test.
        # These stacks drive towards the sample photo's cameraman in track mode, and a camera
        # stack has no laser: said on purpose, as on a robot without one (a test of the laser
        # rules sets no_laser = false; a scan that does come, as the simulator's, is obeyed).
        # The same for the controller's depth map, which a restarted controller takes back.
        "controller": {
            "estop_file": str(tmp / "estop.json"),
            "depth_memory_file": str(tmp / "depth-memory.npz"),
            "mode": "track",
            "no_laser": True,
        },
    }
    for name, values in tables.items():
        base.setdefault(name, {}).update(values)
    lines = []
    for name, values in base.items():
        lines.append(f"[{name}]")
        lines += [f"{k} = {json.dumps(v)}" for k, v in values.items()]
    path = tmp / "stack.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


class Stack:
    """A supervisor process and a test session on the same private endpoint."""

    def __init__(self, config_path: Path, log_path: Path) -> None:
        self.config_path = config_path
        self.config = load_config(config_path, environ={})
        self.keys = Keys(self.config.stack.prefix)
        self.log_path = log_path
        self._log = log_path.open("wb")
        env = {k: v for k, v in os.environ.items() if not k.startswith("STACK__")}
        self.proc = start_supervisor(config_path, self._log, env)
        self.session = self.open("observer")
        self.tokens: list[zenoh.LivelinessToken] = []  # the cameras the test announces

    def open(self, principal: str) -> zenoh.Session:
        """A session of the stack as its role ``principal`` (named as this stack's:
        ``config.principal``). In client mode the supervisor's router may not listen yet, so
        opening is retried until it does."""
        if self.config.zenoh.mode == "peer":
            return open_session(self.config.zenoh, self.config.principal(principal))

        def attempt() -> zenoh.Session | None:
            try:
                return open_session(self.config.zenoh, self.config.principal(principal))
            except ConfigError:
                return None

        session: zenoh.Session = wait_for(attempt, 60, "the supervisor's router to listen")
        return session

    def estop(self, action: str) -> None:
        """``python -m services.controller estop engage|release``, as an operator would."""
        done = subprocess.run(
            [sys.executable, "-m", "services.controller", "estop", action,
             "--config", str(self.config_path), "--reason", "test"],
            cwd=REPO, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr

    def announce(self, camera: str = "", **fields: Any) -> zenoh.LivelinessToken:
        """Announce ``camera`` (default: the first) of the config, as its source would, from
        the test's session: for a test that stands in for the camera (and the detector), the
        controller and the metrics take their cameras from the announcements. The token is
        kept (a token dropped is undeclared) until it is undeclared or the session closes."""
        name = camera or self.config.stack.camera
        msg = announcement(name, self.config.camera_settings(name), **fields)
        key = self.keys.camera_announcement(name, to_chunk(msg))
        token = self.session.liveliness().declare_token(key)
        self.tokens.append(token)
        return token

    def ready_services(self) -> set[str]:
        return ready_services(self.session, self.keys)

    def wait_ready(self, services: set[str], timeout: float = STARTUP_S) -> None:
        try:
            wait_ready(self.session, self.keys, services, self.proc, timeout, poll_s=0.05)
        except StackError as exc:
            pytest.fail(f"waiting for services {sorted(services)}: {exc}:\n{self.log()}")

    def subscribe(self, key: str) -> tuple[zenoh.Subscriber[Any], list[bytes]]:
        received: list[bytes] = []
        sub = self.session.declare_subscriber(key, lambda s: received.append(s.payload.to_bytes()))
        return sub, received

    def metrics(self) -> dict[str, Any] | None:
        return query_metrics(self.session, self.keys, 2.0)

    def log(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")[-6000:]

    def stop(self, timeout: float = 20.0, sig: int = signal.SIGINT) -> int:
        """Signal the supervisor (SIGINT, as Ctrl-C would) and return its exit code."""
        if not stop_supervisor(self.proc, timeout, sig):
            pytest.fail(f"supervisor did not stop within {timeout} s:\n{self.log()}")
        self.session.close()
        self._log.close()
        return self.proc.returncode


def publish_cameras(
    stack: Stack,
    stop: threading.Event,
    cameras: Mapping[str, tuple[tuple[int, int], str]],
    *,
    fill: int,
    box: Callable[[int, int], tuple[float, float, float, float]],
    score: float,
) -> None:
    """Stand in for the cameras and the detector until ``stop``: each camera (name: picture
        size, class) at 10 Hz, each frame filled with ``fill`` and followed by the detections made
        on it, one box ``box(w, h)`` of that camera's class with ``score``. Each camera is announced
    while it publishes."""
    tokens = [stack.announce(name, width=w, height=h) for name, ((w, h), _) in cameras.items()]
    seq = 0
    while not stop.wait(0.1):
        seq += 1
        for name, ((w, h), label) in cameras.items():
            header = Header(stamp_ns=time.time_ns(), frame_id=name, seq=seq, source="test")
            frame = image_to_frame(np.full((h, w, 3), fill, np.uint8), header)
            dets = Detections(
                header=header, image_width=w, image_height=h, class_names=(label,),
                boxes=Boxes(xyxy=np.array([box(w, h)], np.float32),
                            scores=np.array([score], np.float32),
                            class_ids=np.zeros(1, np.int32)),
            )  # fmt: skip
            stack.session.put(stack.keys.frame(name), frame.encode())
            stack.session.put(stack.keys.detections(name), dets.encode())
    for token in tokens:
        token.undeclare()


@pytest.fixture
def make_stack(tmp_path: Path) -> Iterator[Callable[..., Stack]]:
    stacks: list[Stack] = []

    def make(**tables: dict[str, Any]) -> Stack:
        stack = Stack(write_config(tmp_path, **tables), tmp_path / "supervisor.log")
        stacks.append(stack)
        return stack

    yield make
    for stack in stacks:
        if stack.proc.poll() is None:
            stack.stop()
