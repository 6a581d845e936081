"""The detector's handlers and rounds wired as the service wires them (services/detector/
handlers.py, rounds.py, membership.py), on a MemoryHub with a FakeClock and the real default
model: a photo put on a camera's frame key comes back as that camera's Detections, a frame too
old by the fake clock is refused, garbage is counted. In one process, no waits."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from common.bus import QoS, Sample
from common.clock import FakeClock
from common.counters import per_camera
from common.frames import image_to_frame
from common.images import load_sample
from common.memory_bus import MemoryHub
from common.messages import Detections, Frame
from common.node import Node
from perception.pipeline import Detector
from services.detector.contract import DetectorSettings
from services.detector.handlers import DetectorHandlers
from services.detector.membership import PoolMember
from services.detector.rounds import Rounds, camera_outputs
from tests.unit.detector.inprocess import CameraSource, cameras_config

CAMERAS = ("front", "rear")


@pytest.fixture(scope="module")
def detector(default_model: Path) -> Iterator[Detector]:
    """The default model, loaded once for the module."""
    det = Detector.open(default_model, settings=DetectorSettings(model=str(default_model)))
    yield det
    det.close()


class Station:
    """One detector worker on a MemoryHub (its handlers, rounds and pool membership, as
    services/detector/service.py wires them), a camera's participant that puts frames, and a
    probe that hears each camera's detections."""

    def __init__(self, detector: Detector) -> None:
        self.hub = MemoryHub()
        self.clock = FakeClock()
        self.config = config = cameras_config(CAMERAS)
        self.node = node = Node("detector", config, bus=self.hub.join("detector"), clock=self.clock)
        self.handlers = DetectorHandlers(config, node, self.clock)
        outputs = camera_outputs(
            config,
            self.handlers.frame_keys,
            lambda cam: node.publisher(node.keys.detections(cam), QoS.PERCEPTION).put,
        )
        self.rounds = Rounds(config, node, detector, outputs, self.clock)
        self.pool = PoolMember(node, "detector", self.handlers)
        self.source = CameraSource(self.hub)  # the cameras' announcements, as their source's
        for cam in CAMERAS:
            self.source.announce(cam)
        self.pool.join()  # alone: it subscribes to every announced camera's frames
        self.camera = Node("camera", config, bus=self.hub.join("camera"), clock=self.clock)
        self.heard: dict[str, list[Detections]] = {cam: [] for cam in CAMERAS}
        probe = self.hub.join("probe")
        for cam in CAMERAS:
            probe.subscribe(node.keys.detections(cam), self._hear(cam))

    def _hear(self, camera: str) -> Callable[[Sample], None]:
        return lambda sample: self.heard[camera].append(Detections.decode(sample.payload))

    def send(self, camera: str, payload: bytes) -> None:
        self.camera.publisher(self.camera.keys.frame(camera), QoS.SENSOR).put(payload)

    def photo(self, camera: str, sample: str) -> Frame:
        """``sample``'s photo as ``camera``'s frame, stamped now by the fake clock, sent."""
        frame = image_to_frame(load_sample(sample), self.camera.header(frame_id=camera))
        self.send(camera, frame.encode())
        return frame

    def take_round(self) -> int:
        """One round of the loop: what waits, through the model; how many frames it took."""
        waiting = self.handlers.slots.take(len(CAMERAS), 0)
        self.rounds.run(waiting)
        return len(waiting)

    def count(self, name: str, camera: str | None = None) -> int:
        return self.node.counters.get(name if camera is None else per_camera(name, camera))


def test_a_photo_on_each_cameras_key_comes_back_as_its_own_detections(
    detector: Detector,
) -> None:
    st = Station(detector)
    sent_ns = st.clock.wall_ns()
    person = st.photo("front", "astronaut")
    cat = st.photo("rear", "chelsea")
    st.clock.advance(0.05)  # the frames waited 50 ms: fresh
    assert st.take_round() == 2
    (front,) = st.heard["front"]
    (rear,) = st.heard["rear"]
    assert front.header == person.header and rear.header == cat.header
    assert "person" in front.class_names and "person" not in rear.class_names
    assert "cat" in rear.class_names
    assert (front.image_width, front.image_height) == (person.width, person.height)
    # Stamped on the worker's clock: arrival when the camera put it, sent after the round.
    assert front.received_ns == sent_ns and front.published_ns == st.clock.wall_ns()
    assert (st.count("batches"), st.count("batched_frames")) == (1, 2)
    for cam in CAMERAS:
        assert st.count("frames_in", cam) == st.count("detections_out", cam) == 1


def test_a_frame_older_than_max_frame_age_is_counted_stale_and_nothing_published(
    detector: Detector,
) -> None:
    st = Station(detector)
    st.photo("front", "astronaut")
    st.clock.advance(st.config.detector.max_frame_age_s + 0.01)
    assert st.take_round() == 1
    assert st.count("frames_stale") == st.count("frames_stale", "front") == 1
    assert st.heard == {cam: [] for cam in CAMERAS}
    assert st.count("batches") == 0  # it never reached the model
    # The next frame, fresh, is detected on.
    st.photo("front", "astronaut")
    assert st.take_round() == 1 and len(st.heard["front"]) == 1


def test_garbage_on_a_frame_key_is_counted_bad_input_and_dropped(detector: Detector) -> None:
    st = Station(detector)
    st.send("rear", b"\x00garbage")
    assert st.count("frames_in", "rear") == 1
    assert st.count("bad_input") == st.count("bad_input", "rear") == 1
    assert st.handlers.slots.waiting() == 0 and st.take_round() == 0
    assert st.heard == {cam: [] for cam in CAMERAS}
