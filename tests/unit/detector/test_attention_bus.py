"""Attention wired as the service wires it (services/detector/service.py): the controller's
status heard on the bus, the slots' rounds in attention's order, sightings from the real
model's detections, the counters. On a MemoryHub under the secure profile's access rules,
with a FakeClock and the real default model; in one process, no waits."""

from __future__ import annotations

from collections.abc import Iterator
from functools import partial
from pathlib import Path

import pytest

from common.announce import Announcer
from common.bus import QoS
from common.clock import FakeClock
from common.counters import per_camera
from common.frames import image_to_frame
from common.images import load_sample
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import CameraAnnouncement, ControllerStatus
from common.node import Node
from common.settings import principal_names
from perception.pipeline import Detector
from services.detector import contract
from services.detector.attention import Attention
from services.detector.contract import DetectorSettings
from services.detector.handlers import DetectorHandlers
from services.detector.membership import PoolMember
from services.detector.rounds import Rounds, camera_outputs, heed_controller
from stack.access import access_control
from tests.unit.detector.inprocess import cameras_config

CAMERAS = ("front", "left", "rear")


@pytest.fixture(scope="module")
def detector(default_model: Path) -> Iterator[Detector]:
    det = Detector.open(default_model, settings=DetectorSettings(model=str(default_model)))
    yield det
    det.close()


class Station:
    """A worker serving three cameras with attention (floor 0.5 Hz, hold 2 s), a camera's and
    the controller's participants."""

    def __init__(self, detector: Detector) -> None:
        self.clock = FakeClock()
        config = cameras_config(CAMERAS, attention_floor_hz=0.5, attention_hold_s=2.0, max_batch=1)
        # The secure profile's rules: the detector may read the controller's status.
        principals = {cam: f"camera_{cam}" for cam in CAMERAS} | {"front": "camera"}
        keys = Keys(config.stack.prefix)
        acl = access_control(keys, principals, "password")
        self.hub = MemoryHub(acl, names=principal_names(keys.prefix))
        bus = self.hub.join("detector", principal="detector")
        self.node = node = Node("detector", config, bus=bus, clock=self.clock)
        self.handlers = DetectorHandlers(config, node, self.clock)
        s = config.detector
        self.attention = Attention(self.clock, s.attention_floor_hz, s.attention_hold_s)
        node.subscribe(node.keys.controller_status(), heed_controller(node, self.attention))
        outputs = camera_outputs(
            config,
            self.handlers.frame_keys,
            lambda cam: node.publisher(node.keys.detections(cam), QoS.PERCEPTION).put,
        )
        self.rounds = Rounds(config, node, detector, outputs, self.clock, self.attention)
        self.cameras = {
            cam: Node(p, config, bus=self.hub.join(p, principal=p), clock=self.clock)
            for cam, p in principals.items()
        }
        for cam, cam_node in self.cameras.items():  # each source announces its camera
            Announcer(cam_node.bus, partial(keys.camera_announcement, cam)).update(
                CameraAnnouncement(camera=cam, rate_hz=5.0)
            )
        PoolMember(node, "detector", self.handlers).join()
        ctl = self.hub.join("controller", principal="controller")
        self.controller = Node("controller", config, bus=ctl, clock=self.clock)

    def photos(self, sample: str, *cameras: str) -> None:
        for cam in cameras:
            node = self.cameras[cam]
            frame = image_to_frame(load_sample(sample), node.header(frame_id=cam))
            node.publisher(node.keys.frame(cam), QoS.SENSOR).put(frame.encode())

    def status(self, camera: str) -> None:
        self.controller.publisher(self.controller.keys.controller_status(), QoS.TELEMETRY).put(
            ControllerStatus(
                header=self.controller.header(),
                mode="follow",
                target="person",
                state="following",
                camera=camera,
                target_classes=("person",),
            ).encode()
        )

    def take_round(self) -> list[tuple[str, str]]:
        waiting = self.handlers.slots.take(1, 0, self.attention)
        self.rounds.run(waiting)
        self.clock.advance(0.3)  # a round on the CPU
        return [(w.camera, w.reason) for w in waiting]

    def count(self, name: str, camera: str | None = None) -> int:
        return self.node.counters.get(name if camera is None else per_camera(name, camera))


def test_the_locked_camera_goes_first_and_a_camera_that_sees_a_person_gains_priority(
    detector: Detector,
) -> None:
    st = Station(detector)
    # Nothing prioritised yet: the fair order, counted under no reason.
    st.photos("chelsea", "front", "left", "rear")
    assert st.take_round() == [("front", "")]
    st.status("rear")  # the controller's lock is on the rear camera
    assert st.take_round() == [("left", "floor")]  # never taken yet: due for its floor
    assert st.take_round() == [("rear", "priority")]
    assert st.count(contract.ATTENTION_PRIORITY) == st.count("attention_priority", "rear") == 1
    st.photos("chelsea", "front", "rear")
    assert st.take_round() == [("rear", "priority")]  # ahead of front, which waited longer
    # Two seconds (1 / floor) after front was taken it is due, and goes ahead; it sees a
    # person, which gives it priority too.
    st.photos("astronaut", "front")
    st.photos("chelsea", "rear")
    st.clock.advance(1.0)
    st.status("rear")
    assert st.take_round() == [("front", "floor")]
    assert st.attention.priority() == {"front", "rear"}
    assert st.count(contract.ATTENTION_PRIORITY) == 2 and st.count("attention_priority", "front")
    assert st.count(contract.TAKEN_PRIORITY, "rear") == 2
    assert st.count(contract.TAKEN_FLOOR, "left") == st.count(contract.TAKEN_FLOOR, "front") == 1
    assert st.count(contract.TAKEN_PRIORITY) == 2 and st.count(contract.TAKEN_SPARE) == 0


def test_garbage_on_the_controllers_status_is_counted_and_dropped(detector: Detector) -> None:
    st = Station(detector)
    st.controller.publisher(st.controller.keys.controller_status(), QoS.TELEMETRY).put(b"\x00")
    assert st.count("bad_input") == 1
    assert st.attention.priority() == frozenset()


def test_the_taken_counters_are_the_contracts() -> None:
    from services.detector.attention import REASONS

    for reason in REASONS:
        assert contract.taken_for(reason) in contract.COUNTERS & contract.PER_CAMERA
