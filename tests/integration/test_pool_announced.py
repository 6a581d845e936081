"""Issue 31: two real detector workers started from configs that disagree (different camera
tables, different rates) on one stack of three cameras. The cameras are announced on the bus
(CameraAnnouncement, as their sources do: here the test's session stands in for them, and
publishes their frames), so both workers divide the same three cameras, whatever their own
tables say: every camera served by exactly one worker, counted as the distinct publishers
(their Zenoh source ids) of each camera's detections key over a window after settling.

Before, each worker weighed the cameras of its own config: with A's front, left, rear at
10 Hz and B's rear alone at 2 Hz, a camera was served by nobody or by both.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import cv2
import pytest
import zenoh

from common.announce import to_chunk
from common.frames import image_to_frame
from common.images import load_sample
from common.messages import CameraAnnouncement, Header
from common.zenoh_bus import source_of
from tests.integration.conftest import REPO, Stack, wait_for, write_config

pytestmark = pytest.mark.integration

CAMERAS = {"front": "cameraman", "left": "astronaut", "rear": "coffee"}
RATE_HZ = 3.0  # each camera's frames, as announced
WINDOW_S = 4.0  # the window the publishers are counted over, once settled
SETTLE_S = 60.0  # both workers ready and each camera's detections from one of them


class Cameras:
    """The test's stand-in for the camera sources: each camera announced (a liveliness
    token whose key carries its CameraAnnouncement) and its frames published at RATE_HZ."""

    def __init__(self, stack: Stack) -> None:
        self.stack = stack
        keys = stack.keys
        self.tokens = [
            stack.session.liveliness().declare_token(
                keys.camera_announcement(
                    cam, to_chunk(CameraAnnouncement(camera=cam, width=320, height=240,
                                                     rate_hz=RATE_HZ, frame_id=cam,
                                                     source="test"))
                )
            )
            for cam in CAMERAS
        ]  # fmt: skip
        self.images = {
            cam: cv2.resize(load_sample(sample), (320, 240)) for cam, sample in CAMERAS.items()
        }
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        seq = 0
        while not self.done.wait(1.0 / RATE_HZ):
            seq += 1
            for cam, image in self.images.items():
                header = Header(stamp_ns=time.time_ns(), frame_id=cam, seq=seq, source="test")
                frame = image_to_frame(image, header, jpeg_quality=80)
                self.stack.session.put(self.stack.keys.frame(cam), frame.encode())

    def close(self) -> None:
        self.done.set()
        self.thread.join(timeout=10)
        for token in self.tokens:
            token.undeclare()


class Heard:
    """Each camera's detections as they come: (arrival, publisher's source id)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.samples: list[tuple[float, str, str]] = []

    def __call__(self, sample: zenoh.Sample) -> None:
        camera = str(sample.key_expr).split("/")[-2]
        with self.lock:
            self.samples.append((time.monotonic(), camera, source_of(sample)))

    def publishers(self, since: float) -> dict[str, set[str]]:
        """Each camera's distinct publishers (Zenoh session ids) heard since ``since``."""
        out: dict[str, set[str]] = {cam: set() for cam in CAMERAS}
        with self.lock:
            for t, cam, source in self.samples:
                if t >= since and cam in out:
                    out[cam].add(source.split("/")[0])
        return out


@pytest.fixture
def stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stack]:
    tmp = tmp_path_factory.mktemp("pool_announced")
    # Worker A (the supervisor's "detector"): a table of front, left and rear at 10 Hz.
    config = write_config(
        tmp,
        supervisor={"services": ["detector"]},
        stack={"camera": "front"},
        camera={"source": "sample:cameraman", "rate_hz": 10.0},
        **{f"cameras.{c}": {"source": "sample:coffee", "frame_id": c} for c in ("left", "rear")},
        detector={"imgsz": 320, "capacity_hz": 10.0},
    )
    stack = Stack(config, tmp / "supervisor.log")
    try:
        yield stack
    finally:
        if stack.proc.poll() is None:
            assert stack.stop() == 0, stack.log()


def test_two_workers_whose_configs_disagree_serve_every_announced_camera_once(
    stack: Stack, tmp_path_factory: pytest.TempPathFactory
) -> None:
    keys = stack.keys
    heard = Heard()
    sub = stack.session.declare_subscriber(keys.all_detections(), heard)
    cameras = Cameras(stack)
    # Worker B, another host's config: its table names rear alone, at 2 Hz, and another
    # first camera; the same bus and prefix.
    other = write_config(
        tmp_path_factory.mktemp("other_table"),
        zenoh={"endpoint": stack.config.zenoh.endpoint, "multicast_scouting": False},
        stack={"prefix": keys.prefix, "camera": "rear"},
        camera={"source": "sample:coffee", "rate_hz": 2.0},
        detector={"imgsz": 320, "workers": 2, "capacity_hz": 10.0},
    )
    log = tmp_path_factory.mktemp("worker_b") / "worker_b.log"
    with log.open("wb") as out:
        worker = subprocess.Popen(
            [sys.executable, "-m", "services.detector", "serve",
             "--config", str(other), "--worker", "detector_2"],
            cwd=REPO, stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip
    try:
        stack.wait_ready({"detector", "detector_2"})

        def split() -> dict[str, set[str]] | None:
            """Each camera's publishers over the last window, once each has exactly one
            and the two workers share the cameras."""
            got = heard.publishers(time.monotonic() - WINDOW_S)
            one_each = all(len(s) == 1 for s in got.values())
            return got if one_each and len(set().union(*got.values())) == 2 else None

        def why() -> str:
            return (
                f"one publisher per camera: {heard.publishers(time.monotonic() - WINDOW_S)}\n"
                f"{stack.log()}\nworker B:\n{log.read_text(errors='replace')[-3000:]}"
            )

        wait_for(split, SETTLE_S, why)
        # Joining, the workers' views differ for a moment (each serves what it thinks is its
        # own until it hears the other), and a worker's first round, still running then, may
        # publish late: a window passes before the one that counts.
        settled = time.monotonic()
        wait_for(lambda: time.monotonic() - settled > WINDOW_S, WINDOW_S * 3, "a window")
        # A whole window more, settled: still each camera from exactly one publisher.
        start = time.monotonic()
        wait_for(lambda: time.monotonic() - start > WINDOW_S, WINDOW_S * 3, "a window")
        window = heard.publishers(start)
        assert all(len(s) == 1 for s in window.values()), window
        with heard.lock:
            counts = {c: sum(1 for t, cam, _ in heard.samples if cam == c and t >= start)
                      for c in CAMERAS}  # fmt: skip
        assert all(n >= 2 for n in counts.values()), counts
    finally:
        worker.send_signal(signal.SIGINT)
        assert worker.wait(timeout=30) == 0, log.read_text(errors="replace")[-3000:]
        cameras.close()
        sub.undeclare()
