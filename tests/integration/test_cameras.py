"""Several cameras under the supervisor: one process per camera, each its own service, each
on its own key and announcing its camera; a killed camera is restarted alone while the others
keep publishing, and its announcement goes with it (and comes back with the restart)."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from common.announce import Announced
from common.messages import CameraAnnouncement, Detections, Frame
from common.zenoh_bus import ZenohBus
from tests.integration.conftest import REPO, Stack, wait_for, write_config
from tools.launch import service_pids

pytestmark = pytest.mark.integration

SOURCES = {"front": "sample:chelsea", "rear": "sample:coffee", "left": "sample:astronaut"}
SERVICES = {"front": "camera", "rear": "camera_rear", "left": "camera_left"}
FURTHER: dict[str, Any] = {
    "cameras.rear": {"source": SOURCES["rear"], "mount_yaw_deg": 180.0, "frame_id": "rear"},
    "cameras.left": {"source": SOURCES["left"], "mount_yaw_deg": 90.0, "frame_id": "left"},
}


class Announcements:
    """Every camera's announcement as a pool worker sees it (common.announce.Announced on the
    test's session), and which cameras were announced after each change: (monotonic time,
    names)."""

    def __init__(self, stack: Stack) -> None:
        self.changes: list[tuple[float, set[str]]] = []
        self._started = threading.Event()
        keys = stack.keys
        self.heard: Announced[CameraAnnouncement] = Announced(
            ZenohBus(stack.session),  # not closed here: the stack closes its session
            keys.all_camera_announcements(),
            keys.camera_announcement_parts,
            CameraAnnouncement.decode,
            lambda a: a.camera,
            on_change=self._changed,
        )
        self._started.set()

    def _changed(self) -> None:
        if self._started.is_set():
            self.changes.append((time.monotonic(), set(self.heard.current())))


class Arrivals:
    """Each camera's frames as they arrive: (monotonic time, decoded Frame)."""

    def __init__(self, stack: Stack) -> None:
        self._lock = threading.Lock()
        self.frames: dict[str, list[tuple[float, Frame]]] = {c: [] for c in SOURCES}
        self._subs = [
            stack.session.declare_subscriber(stack.keys.frame(c), self._on(c)) for c in SOURCES
        ]

    def _on(self, camera: str) -> Any:
        def on_sample(sample: Any) -> None:
            frame = Frame.decode(sample.payload.to_bytes())
            with self._lock:
                self.frames[camera].append((time.monotonic(), frame))

        return on_sample

    def since(self, camera: str, t: float) -> list[Frame]:
        with self._lock:
            return [f for at, f in self.frames[camera] if at > t]


def test_each_camera_is_a_process_and_a_killed_one_restarts_alone(make_stack) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(
        camera={"source": SOURCES["front"], "rate_hz": 4.0},
        supervisor={"services": ["camera", "detector", "metrics"], "restart_backoff_s": 0.2},
        **FURTHER,
    )
    arrivals = Arrivals(stack)
    announced = Announcements(stack)
    dets = {c: stack.subscribe(stack.keys.detections(c))[1] for c in SOURCES}

    def detected_since(camera: str, t: float) -> list[Detections]:
        """``camera``'s detections of frames captured after monotonic time ``t``."""
        sent = {f.header.stamp_ns for f in arrivals.since(camera, t)}
        found = [Detections.decode(d) for d in list(dets[camera])]
        return [d for d in found if d.header.stamp_ns in sent]

    stack.wait_ready({*SERVICES.values(), "detector", "metrics"})

    # Every camera's frames on its own key, from its own process, with its own frame id.
    for camera, service in SERVICES.items():
        frames = wait_for(lambda c=camera: arrivals.since(c, 0), 30, f"{camera}'s frames")
        assert frames[-1].header.source == service
        assert frames[-1].header.frame_id == ("camera" if camera == "front" else camera)
    sizes = {c: arrivals.since(c, 0)[-1].width for c in SOURCES}
    assert len(set(sizes.values())) == 3, sizes  # three different photos, one per camera
    # Each camera announced by its process, with its settings and its photo's size.
    expected = {
        camera: CameraAnnouncement(
            camera=camera, width=f.width, height=f.height, rate_hz=4.0,
            mount_yaw_deg={"front": 0.0, "rear": 180.0, "left": 90.0}[camera], hfov_deg=60.0,
            frame_id=f.header.frame_id, source="camera",
        )
        for camera in SOURCES
        for f in arrivals.since(camera, 0)[-1:]
    }  # fmt: skip

    def without_session() -> dict[str, CameraAnnouncement]:
        """The announcements heard, less the announcing session's id (each process's own)."""
        heard = announced.heard.current()
        assert all(a.zid for a in heard.values()), heard  # each says who publishes it
        return {c: dataclasses.replace(a, zid="") for c, a in heard.items()}

    wait_for(
        lambda: without_session() == expected,
        30,
        lambda: f"each camera's announcement {expected}, got {announced.heard.current()}",
    )
    zids = {a.zid for a in announced.heard.current().values()}
    assert len(zids) == len(SOURCES), zids  # a process, so a session, per camera
    # One detector serves every camera: each camera's detections on its own key, carrying
    # the stamp of a frame that camera sent and that camera's frame id.
    for camera in SOURCES:
        got = wait_for(lambda c=camera: detected_since(c, 0), 120, f"{camera}'s detections")
        assert got[-1].header.frame_id == ("camera" if camera == "front" else camera)
    # The supervisor shows each camera process.
    wait_for(
        lambda: all(f"{s}:ready" in stack.log() for s in SERVICES.values()),
        10,
        lambda: f"every camera process in the status line:\n{stack.log()}",
    )
    # Each camera's counters are its own (and the metrics service believes them).
    counters = wait_for(
        lambda: (m := stack.metrics()) and all(
            m["counters"].get(f"{s}.frames_out", 0) > 0 for s in SERVICES.values()
        ) and m["counters"],
        30, "every camera's counters in the metrics",
    )  # fmt: skip
    assert not any(k.endswith("refused.unknown_service") for k in counters), counters

    pids = {s: service_pids(s, stack.config_path) for s in SERVICES.values()}
    assert all(len(p) == 1 for p in pids.values()), pids
    (killed,) = pids["camera_left"]
    killed_at = time.monotonic()
    os.kill(killed, signal.SIGKILL)

    def restarted() -> list[int]:
        return [p for p in service_pids("camera_left", stack.config_path) if p != killed]

    wait_for(restarted, 30, "the supervisor to restart camera_left")
    # Its announcement went with the killed process (the router dropped its session's
    # tokens) and came back with the new one; the others' stayed.
    wait_for(
        lambda: [t for t, names in announced.changes if t > killed_at and "left" not in names],
        30,
        lambda: f"left's announcement to go after the SIGKILL: {announced.changes}",
    )
    before = {c: a.zid for c, a in announced.heard.current().items()}
    wait_for(
        lambda: without_session() == expected,
        60,
        lambda: f"left announced again after its restart: {announced.heard.current()}",
    )
    # ... by its new process, from a session of its own; the others' unchanged.
    now = {c: a.zid for c, a in announced.heard.current().items()}
    assert now["left"] not in zids and all(now[c] == before[c] for c in ("front", "rear")), now
    after = [names for t, names in announced.changes if t > killed_at]
    assert all({"front", "rear"} <= names for names in after), after
    first_new = wait_for(
        lambda: arrivals.since("left", killed_at + 0.2), 60, "left's frames after the restart"
    )[0]
    back_at = next(at for at, f in arrivals.frames["left"] if f is first_new)
    # While it was down, the other two went on publishing, from the same processes.
    for camera in ("front", "rear"):
        during = [at for at, _ in arrivals.frames[camera] if killed_at < at < back_at]
        assert len(during) >= 2, (camera, back_at - killed_at)
    for service in ("camera", "camera_rear"):
        assert service_pids(service, stack.config_path) == pids[service], service
    # ... and the detector went on serving them: detections of frames captured meanwhile.
    for camera in ("front", "rear"):
        wait_for(
            lambda c=camera: detected_since(c, killed_at), 60, f"{camera} served after the kill"
        )
    wait_for(
        lambda: "camera_left:ready(r1)" in stack.log(),
        10,
        lambda: f"the status line to show camera_left's restart:\n{stack.log()}",
    )
    log = stack.log()
    assert "camera_left: exited with code -9" in log
    assert "camera: exited" not in log and "camera_rear: exited" not in log
    assert "camera:ready(r" not in log and "camera_rear:ready(r" not in log
    assert stack.stop() == 0, stack.log()


def test_a_further_camera_that_cannot_open_stops_the_stack_naming_it(tmp_path: Path) -> None:
    config = write_config(
        tmp_path,
        supervisor={"services": ["camera"]},
        **{"cameras.rear": {"source": str(tmp_path / "missing.png"), "frame_id": "rear"}},
    )
    done = subprocess.run(
        [sys.executable, "-m", "deploy.supervisor", "--config", str(config), "--duration", "30"],
        cwd=REPO, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr[-3000:]
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("supervisor: error: camera_rear: error: "), last
    assert "missing.png" in last and "(exit code 2; not restarted)" in last, last
    assert "Traceback" not in done.stderr


def test_serve_names_an_unknown_camera(tmp_path: Path) -> None:
    config = write_config(tmp_path, **{"cameras.rear": {"frame_id": "rear"}})
    done = subprocess.run(
        [sys.executable, "-m", "services.camera", "serve", "--config", str(config),
         "--camera", "back"],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "camera: error: no camera 'back' in the config; known: ['front', 'rear']"
    )
