"""The secure profile with two cameras (issue 22): each camera process joins as its own principal
and may put only its own camera's frames and announce only its own camera; the detector puts
every camera's detections and no frame. Real camera processes, real sessions and the router's
real access control: a refused put never reaches a listener that may read its key, a refused
token never a liveliness subscriber.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh

from common.announce import from_chunk, to_chunk
from common.clock import now
from common.frames import image_to_frame
from common.messages import CameraAnnouncement, Detections, Frame, Header
from common.security import stack_principals
from common.spawn import spawn, stop_child
from tests.integration.conftest import (
    REPO,
    Stack,
    credentials_for,
    free_port,
    wait_for,
    write_config,
)
from tests.integration.test_safety import person

pytestmark = pytest.mark.integration

# camera -> its principal (common.settings.camera_service); each sends its own frame_id.
CAMERAS = {"front": "camera", "rear": "camera_rear"}
FRAME_IDS = {"front": "front_cam", "rear": "rear_cam"}
# Each forbidden put is followed by an allowed one from the same session (same link, same
# priority, delivered in order): this many allowed puts arrived means the forbidden ones
# before them would have too.
ALLOWED_PUTS = 10


def secure_two_camera_stack(make_stack: Any, tmp_path: Path, auth: str) -> Stack:
    creds = tmp_path / "credentials"
    prefix = credentials_for(creds, stack_principals(CAMERAS))
    table = {"mode": "client", "auth": auth, "credentials_dir": str(creds)}
    if auth == "certificate":  # mutual TLS: each camera proves itself with its own key
        table["endpoint"] = f"tls/127.0.0.1:{free_port()}"
    # The supervisor runs no camera: the test starts each camera's process itself, so that
    # exactly the two principals below put frames, however a supervisor starts cameras.
    stack: Stack = make_stack(
        zenoh=table,
        stack={"prefix": prefix},
        supervisor={"services": ["metrics"]},
        camera={"frame_id": FRAME_IDS["front"], "rate_hz": 5.0},
        **{"cameras.rear": {"frame_id": FRAME_IDS["rear"], "mount_yaw_deg": 180.0}},
    )
    stack.wait_ready({"metrics"})
    return stack


@pytest.fixture
def cameras() -> Iterator[dict[str, subprocess.Popen[bytes]]]:
    """Started camera processes by camera name; each must stop cleanly on SIGINT."""
    procs: dict[str, subprocess.Popen[bytes]] = {}
    yield procs
    for proc in procs.values():  # a test that failed before stopping them
        if proc.poll() is None:
            stop_child(proc, 20)


def start_camera(stack: Stack, camera: str, log: Path) -> subprocess.Popen[bytes]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("STACK__")}
    with log.open("wb") as out:
        return spawn(
            [sys.executable, "-m", "services.camera", "serve", "--camera", camera,
             "--config", str(stack.config_path)],
            env=env, cwd=REPO, stdout=out, stderr=subprocess.STDOUT,
        )  # fmt: skip


def marked_frame(source: str, frame_id: str = "rogue") -> bytes:
    at = now()
    header = Header(stamp_ns=at.wall_ns, frame_id=frame_id, seq=1, source=source)
    return image_to_frame(np.zeros((8, 8, 3), np.uint8), header).encode()


def put_until_allowed_arrive(
    session: zenoh.Session,
    forbidden: dict[str, bytes],
    allowed: dict[str, bytes],
    arrived: Any,
    what: str,
) -> None:
    """Put each forbidden payload, then each allowed one, until ``arrived()`` counts
    ``ALLOWED_PUTS`` of every allowed key's."""
    pubs = {key: session.declare_publisher(key) for key in (*forbidden, *allowed)}

    def round_() -> bool:
        for key, payload in (*forbidden.items(), *allowed.items()):
            pubs[key].put(payload)
        return all(arrived(key) >= ALLOWED_PUTS for key in allowed)

    wait_for(round_, 30, what)
    for pub in pubs.values():
        pub.undeclare()


@pytest.mark.parametrize("auth", ["password", "certificate"])
def test_each_camera_puts_only_its_own_frames_and_the_detector_only_detections(
    make_stack: Any, tmp_path: Path, cameras: dict[str, subprocess.Popen[bytes]], auth: str
) -> None:
    stack = secure_two_camera_stack(make_stack, tmp_path, auth)
    keys = stack.keys
    frame_keys = {c: keys.frame(c) for c in CAMERAS}
    # Listeners with read rights: the viewer may read every camera's frames, the observer
    # every camera's detections.
    viewer = stack.open("viewer")
    frames: list[tuple[str, Header]] = []
    viewer.declare_subscriber(
        keys.all_frames(),
        lambda s: frames.append((str(s.key_expr), Frame.decode(s.payload.to_bytes()).header)),
    )
    _, dets = stack.subscribe(keys.all_detections())

    # The real camera processes, each as its own principal with its own credentials.
    for camera in CAMERAS:
        cameras[camera] = start_camera(stack, camera, tmp_path / f"camera-{camera}.log")
    stack.wait_ready(set(CAMERAS.values()), timeout=60)

    def from_(key: str, source: str) -> int:
        return sum(1 for k, h in list(frames) if k == key and h.source == source)

    def camera_frames(camera: str) -> list[Header]:
        """What the camera processes put on ``camera``'s key (their header names their service)."""
        mine = set(CAMERAS.values())
        return [h for k, h in list(frames) if k == frame_keys[camera] and h.source in mine]

    wait_for(lambda: all(len(camera_frames(c)) >= 3 for c in CAMERAS), 30, "each camera's frames")
    announced: set[str] = set()  # the announcement tokens alive, as the observer sees them

    def on_token(sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        (announced.add if sample.kind == zenoh.SampleKind.PUT else announced.discard)(key)

    stack.session.liveliness().declare_subscriber(
        keys.all_camera_announcements(), on_token, history=True
    )

    def announced_by_processes() -> dict[str, CameraAnnouncement]:
        """Each camera's announcement as its process made it (source ``camera``)."""
        out = {}
        for key in list(announced):
            parts = keys.camera_announcement_parts(key)
            if parts is not None:
                msg = from_chunk(CameraAnnouncement.decode, parts[1])
                if msg.source == "camera":
                    out[parts[0]] = msg
        return out

    # Each camera process's own announcement is let through by the router.
    got = wait_for(
        lambda: (a := announced_by_processes()).keys() == CAMERAS.keys() and a,
        30,
        lambda: f"each camera process's announcement: {sorted(announced)}",
    )
    assert {c: (a.frame_id, a.mount_yaw_deg) for c, a in got.items()} == {
        "front": (FRAME_IDS["front"], 0.0), "rear": (FRAME_IDS["rear"], 180.0)
    }  # fmt: skip

    sessions = {p: stack.open(p) for p in ("camera", "camera_rear", "detector")}
    try:
        # A camera's principal may not announce the other camera: its token on the other's
        # key never arrives, while its token on its own key (declared after it) does.
        for camera, principal in CAMERAS.items():
            (other,) = set(CAMERAS) - {camera}
            fake = to_chunk(CameraAnnouncement(camera=other, rate_hz=99.0, source=principal))
            own = to_chunk(CameraAnnouncement(camera=camera, rate_hz=99.0, source=principal))
            forged = (
                sessions[principal]
                .liveliness()
                .declare_token(keys.camera_announcement(other, fake))
            )
            mine = (
                sessions[principal]
                .liveliness()
                .declare_token(keys.camera_announcement(camera, own))
            )
            wait_for(
                lambda c=camera, o=own: keys.camera_announcement(c, o) in announced,
                30,
                f"{principal}'s announcement of its own camera",
            )
            assert keys.camera_announcement(other, fake) not in announced, (
                f"{principal} announced camera {other}"
            )
            forged.undeclare()
            mine.undeclare()
        # Each camera's principal: the other camera's key is refused, its own is not.
        for camera, principal in CAMERAS.items():
            (other,) = set(CAMERAS) - {camera}
            forbidden = {frame_keys[other]: marked_frame(f"rogue-{principal}")}
            allowed = {frame_keys[camera]: marked_frame(f"own-{principal}")}
            put_until_allowed_arrive(
                sessions[principal],
                forbidden,
                allowed,
                lambda key, p=principal: from_(key, f"own-{p}"),
                f"{principal}'s puts on its own frame key",
            )
            assert from_(frame_keys[other], f"rogue-{principal}") == 0, (
                f"{principal} put frames on camera {other}'s key"
            )

        # The detector: refused on every frame key, allowed on every camera's detections.
        def detections_from(key: str) -> int:
            return sum(
                1
                for d in map(Detections.decode, list(dets))
                if d.header.source == "own-detector" and keys.detections(d.header.frame_id) == key
            )

        own = {
            keys.detections(c): person(
                Header(stamp_ns=now().wall_ns, frame_id=c, seq=1, source="own-detector")
            ).encode()
            for c in CAMERAS
        }
        put_until_allowed_arrive(
            sessions["detector"],
            {key: marked_frame("rogue-detector") for key in frame_keys.values()},
            own,
            detections_from,
            "the detector's detections on every camera's key",
        )
        rogue = [k for k, h in list(frames) if h.source == "rogue-detector"]
        assert rogue == [], f"the detector put frames on {sorted(set(rogue))}"
    finally:
        for session in (*sessions.values(), viewer):
            session.close()

    # The cameras' own frames kept arriving, each only on its own key.
    for camera in CAMERAS:
        seen = {(h.source, h.frame_id) for h in camera_frames(camera)}
        assert seen == {(CAMERAS[camera], FRAME_IDS[camera])}, (camera, seen)
    for camera, proc in cameras.items():
        assert stop_child(proc, 20) and proc.returncode == 0, f"camera {camera}"
    assert stack.stop() == 0, stack.log()


def test_the_stack_refuses_credentials_made_for_fewer_cameras(tmp_path: Path) -> None:
    creds = tmp_path / "credentials"
    prefix = credentials_for(creds)  # a one-camera stack's principals: no camera_rear
    config = write_config(
        tmp_path,
        zenoh={"mode": "client", "auth": "password", "credentials_dir": str(creds)},
        stack={"prefix": prefix},
        # The camera service runs (the refusal comes before any process starts): a stack
        # that runs no camera needs no camera secret (zstack credentials makes none).
        supervisor={"services": ["camera", "metrics"]},
        **{"cameras.rear": {"mount_yaw_deg": 180.0}},
    )
    env = {k: v for k, v in os.environ.items() if not k.startswith("STACK__")}
    done = subprocess.run(
        [sys.executable, "-m", "deploy.supervisor", "--config", str(config)],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert "camera_rear" in line, line
    assert f"zstack credentials --config {config} --force" in line, line
