"""The recorder with two cameras: the recorder service records each camera's frames and
detections on that camera's own ROS topics (read back with mcap + mcap_ros2, a reader we did
not write), ``compare``'s reader keys them by camera, and ``play`` puts each camera's frames back
on its own key. This test stands in for the cameras and the detector."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from common.announce import Announced
from common.messages import CameraAnnouncement, Frame, ServiceCounters
from common.zenoh_bus import ZenohBus
from tests.integration.conftest import REPO, Stack, publish_cameras, wait_for
from tools.compare.runs import load_run

pytestmark = pytest.mark.integration

REAR = {"cameras.rear": {"mount_yaw_deg": 180.0}}
# Each camera's picture size and its detections' class: told apart on arrival.
CAMERAS = {"front": ((64, 48), "person"), "rear": ((96, 32), "dog")}
TOPICS = {
    "/camera/rgb/image_raw": "front", "/detections": "front",
    "/rear/camera/rgb/image_raw": "rear", "/rear/detections": "rear",
}  # fmt: skip


def _publish(stack: Stack, stop: threading.Event) -> None:
    publish_cameras(stack, stop, CAMERAS, fill=90, box=lambda w, h: (1, 1, 9, 9), score=0.8)


def test_two_cameras_recorded_compared_and_played_per_camera(make_stack, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    stack: Stack = make_stack(
        supervisor={"services": ["recorder"]},
        # Niced, not SCHED_IDLE: this test is about what is written, and an idle-class
        # process gets next to no CPU while both cores are busy (a loaded CI machine). The
        # priority as shipped is test_recorder.py's _check_priority.
        recorder={"output_dir": str(tmp_path / "rec"), "flush_period_s": 0.5, "sched_idle": False},
        **REAR,
    )
    stack.wait_ready({"recorder"})
    _, counts = stack.subscribe(stack.keys.counters("recorder"))
    stop = threading.Event()
    threading.Thread(target=_publish, args=(stack, stop), daemon=True).start()
    try:
        wait_for(
            lambda: counts and ServiceCounters.decode(counts[-1]).counters.get("written", 0) >= 40,
            30,
            "the recorder to write both cameras' messages",
        )
    finally:
        stop.set()
    assert stack.stop() == 0, stack.log()
    (recording,) = (tmp_path / "rec").glob("stack-*.mcap")

    # Each camera's frames and detections on its own ROS topics, decoded by mcap_ros2.
    seen: dict[str, set[object]] = {topic: set() for topic in TOPICS}
    with recording.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(topics=sorted(TOPICS)):
            if "detections" in channel.topic:
                seen[channel.topic] |= {r.hypothesis.class_id for d in msg.detections
                                        for r in d.results}  # fmt: skip
            else:
                seen[channel.topic].add((msg.width, msg.height))
    for topic, camera in TOPICS.items():
        (size, label) = CAMERAS[camera]
        assert seen[topic] == ({label} if "detections" in topic else {size}), (topic, seen[topic])

    # compare's reader: each frame by (camera, seq), the cameras' detections never mixed.
    run = load_run(recording)
    assert {c for c, _ in run.detections} == set(CAMERAS)
    for (camera, _seq), dets in run.detections.items():
        assert dets.class_names == (CAMERAS[camera][1],)

    # play: each camera's frames back on its own key.
    fresh: Stack = make_stack(supervisor={"services": ["metrics"]}, **REAR)
    fresh.wait_ready({"metrics"})
    frames = {name: fresh.subscribe(fresh.keys.frame(name))[1] for name in CAMERAS}
    heard = Announced(
        ZenohBus(fresh.session),  # not closed here: the stack closes its session
        fresh.keys.all_camera_announcements(),
        fresh.keys.camera_announcement_parts,
        CameraAnnouncement.decode,
        lambda a: a.camera,
    )
    player = subprocess.Popen(
        [sys.executable, "-m", "services.recorder", "play", str(recording), "--loop",
         "--no-wait", "--config", str(fresh.config_path)],  # no detector there: on purpose
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    try:
        wait_for(
            lambda: all(len(f) >= 3 for f in frames.values()),
            60,
            lambda: f"replayed frames on both keys { {n: len(f) for n, f in frames.items()} }",
        )
        # ... each camera announced by the player while it plays, at its recorded size.
        wanted = {c: (size, "play") for c, (size, _) in CAMERAS.items()}
        wait_for(
            lambda: (
                {c: ((a.width, a.height), a.source) for c, a in heard.current().items()} == wanted
            ),
            20,
            lambda: f"both cameras announced by the player: {heard.current()}",
        )
    finally:
        player.send_signal(signal.SIGINT)
        assert player.wait(20) == 0
    wait_for(lambda: not heard.current(), 20, "the announcements to go when the play ends")
    for name, (size, _label) in CAMERAS.items():
        sizes = {(f.width, f.height) for f in map(Frame.decode, list(frames[name]))}
        assert sizes == {size}, (name, sizes)
    assert fresh.stop() == 0, fresh.log()
