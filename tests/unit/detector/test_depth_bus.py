"""The detector's depth stage wired as the service wires it (services/detector/membership.py,
handlers.py, rounds.py, depth_stage.py), on a MemoryHub with a FakeClock and a real ONNX
Runtime backend on a tiny model whose boxes are known (tests/unit/detector/halves.py: one box
in each bright half of a 32x32 image). A camera announced with depth gets a depth
subscription; its frames' detections get every depth column from the depth frame of the same
stamp, in batched rounds and with the tracker; a frame without depth, a camera without depth,
garbage on the depth key and an announcement that drops depth are each handled and counted."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from common.bus import QoS, Sample
from common.clock import FakeClock
from common.counters import per_camera
from common.frames import image_to_frame
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import DepthFrame, Detections, Frame, Header
from common.node import Node
from common.settings import principal_names
from perception.depth import COLUMNS
from perception.pipeline import Detector
from services.detector.handlers import DetectorHandlers
from services.detector.membership import PoolMember
from services.detector.rounds import Rounds
from services.detector.service import ServedCameras
from stack.access import access_control
from tests.unit.detector.depthimage import flat_depth
from tests.unit.detector.halves import SIDE, halves_model, image
from tests.unit.detector.inprocess import CameraSource, cameras_config

CAMERAS = ("front", "rear")
LEFT_BOX = (2.0, 10.0, 14.0, 22.0)  # the halves model's left box, in pixels of a 32x32 frame
METRES = 2.5


class Station:
    """One detector worker (its handlers, rounds, pool membership and served cameras, as
    services/detector/service.py wires them), a camera source that announces ``front`` with
    depth and ``rear`` without, a camera that puts frames and depth frames, and a probe that
    hears each camera's detections."""

    def __init__(self, detector: Detector, **settings: Any) -> None:
        self.hub = MemoryHub()
        self.clock = FakeClock()
        self.config = config = cameras_config(CAMERAS, max_batch=2, **settings)
        self.node = node = Node("detector", config, bus=self.hub.join("detector"), clock=self.clock)
        self.handlers = DetectorHandlers(config, node, self.clock, frame_keys={})
        self.cameras = ServedCameras(config, node, self.handlers, "{}")
        self.rounds = Rounds(
            config, node, detector, self.cameras.outputs, self.clock, depth=self.handlers.depth
        )
        self.pool = PoolMember(
            node,
            "detector",
            self.handlers,
            on_gained=self.cameras.gained,
            on_lost=self.cameras.lost,
        )
        self.source = CameraSource(self.hub)
        self.source.announce("front", depth=True)
        self.source.announce("rear")
        self.pool.join()
        self.camera = Node("camera", config, bus=self.hub.join("camera"), clock=self.clock)
        self.heard: dict[str, list[Detections]] = {cam: [] for cam in CAMERAS}
        probe = self.hub.join("probe")
        for cam in CAMERAS:
            probe.subscribe(node.keys.detections(cam), self._hear(cam))

    def _hear(self, camera: str) -> Callable[[Sample], None]:
        return lambda sample: self.heard[camera].append(Detections.decode(sample.payload))

    def settle(self) -> None:
        """What the loop does between rounds with the pool (announcements heard)."""
        self.pool.beat()
        self.pool.settle()

    def frame(self, camera: str) -> Frame:
        """A 32x32 frame of ``camera`` with both halves bright (two boxes), stamped now (50 ms
        after the last: a 20 Hz camera), sent."""
        self.clock.advance(0.05)
        frame = image_to_frame(image(True, True), self.camera.header(frame_id=camera))
        self.put(self.camera.keys.frame(camera), frame.encode())
        return frame

    def depth(self, camera: str, header: Header, size: int = SIDE, **kw: Any) -> DepthFrame:
        """A flat depth frame at METRES with ``header``, ``size`` x ``size``, sent."""
        depth = flat_depth(header, size, size, METRES, **kw)
        self.put(self.camera.keys.depth(camera), depth.encode())
        return depth

    def put(self, key: str, payload: bytes) -> None:
        self.camera.publisher(key, QoS.SENSOR).put(payload)

    def take_round(self) -> int:
        waiting = self.handlers.slots.take(len(CAMERAS), 0)
        self.rounds.run(waiting)
        return len(waiting)

    def count(self, name: str, camera: str | None = None) -> int:
        return self.node.counters.get(name if camera is None else per_camera(name, camera))

    def last(self, camera: str) -> Detections:
        return self.heard[camera][-1]


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return halves_model(tmp_path_factory.mktemp("halves"))


@pytest.fixture
def st(model: Path) -> Station:
    config = cameras_config(CAMERAS, max_batch=2, model=str(model))
    detector = Detector.open(model, settings=config.detector, max_batch=2)
    return Station(detector, model=str(model))


def centre_back_projected(det: Detections, row: int, depth: DepthFrame) -> tuple[float, float]:
    """Where row ``row``'s 3D centre lands in the colour frame (pixels)."""
    c = det.boxes.columns
    sx, sy = det.image_width / depth.width, det.image_height / depth.height
    u = (depth.fx * float(c["x_m"][row]) / float(c["z_m"][row]) + depth.cx) * sx
    v = (depth.fy * float(c["y_m"][row]) / float(c["z_m"][row]) + depth.cy) * sy
    return u, v


def test_a_frame_with_its_depth_gets_every_depth_column_in_a_batched_tracked_round(
    st: Station,
) -> None:
    front, rear = st.frame("front"), st.frame("rear")
    depth = st.depth("front", front.header)
    assert st.take_round() == 2  # one batch of both cameras
    det = st.last("front")
    assert len(det.boxes) == 2 and det.boxes.track_ids is not None
    assert set(det.boxes.columns) == set(COLUMNS)
    np.testing.assert_allclose(det.boxes.columns["z_m"], METRES, atol=0.01)
    i = int(np.argmin(det.boxes.xyxy[:, 0]))  # the left box
    np.testing.assert_allclose(det.boxes.xyxy[i], LEFT_BOX, atol=0.5)
    u, v = centre_back_projected(det, i, depth)
    assert (u, v) == pytest.approx((8.0, 16.0), abs=0.5)  # the box's centre
    x, y, z = (float(det.boxes.columns[k][i]) for k in ("x_m", "y_m", "z_m"))
    assert float(det.boxes.columns["distance_m"][i]) == pytest.approx(math.hypot(x, y, z))
    assert float(det.boxes.columns["size_x_m"][i]) == pytest.approx(12 * METRES / depth.fx, 0.05)
    assert det.timing_ms["depth"] >= 0
    # The camera without depth: 2D, nothing counted for it.
    assert st.last("rear").header == rear.header
    assert st.last("rear").boxes.columns == {} and "depth" not in st.last("rear").timing_ms
    assert st.count("depth_in", "front") == st.count("depth_paired", "front") == 1
    assert st.count("depth_unpaired") == 0 and st.count("depth_paired", "rear") == 0


def test_a_depth_frame_arriving_after_its_colour_frame_or_while_the_model_runs_is_paired(
    st: Station,
) -> None:
    first = st.frame("front")  # no depth yet when it arrives
    st.depth("front", first.header)
    assert st.take_round() == 1
    assert set(st.last("front").boxes.columns) == set(COLUMNS)
    # One arriving while the model runs (the round took its frame already).
    second = st.frame("front")
    real = st.rounds.detector

    class DepthDuringInference:
        def __getattr__(self, name: str) -> Any:
            return getattr(real, name)

        def detect_batch(self, images: Any) -> Any:
            st.depth("front", second.header)
            # The next frame comes meanwhile, and depth 30 times a second: its depth frame
            # is out of the buffer before the detections are built.
            third = st.frame("front")
            for n in range(st.config.detector.depth_buffer):
                at = third.header.stamp_ns + n * 33_000_000
                st.depth("front", replace(third.header, stamp_ns=at))
            return real.detect_batch(images)

    st.rounds.detector = DepthDuringInference()  # type: ignore[assignment]
    assert st.take_round() == 1
    assert st.last("front").header == second.header
    assert set(st.last("front").boxes.columns) == set(COLUMNS)
    assert st.count("depth_paired", "front") == 2
    assert st.take_round() == 1  # the third frame, whose own depth is there
    assert st.count("depth_paired", "front") == 3


def test_a_frame_without_depth_within_the_tolerance_is_2d_and_counted_unpaired(
    st: Station,
) -> None:
    frame = st.frame("front")
    tolerance_ns = round(st.config.detector.depth_pair_tolerance_ms * 1e6)
    late = replace(frame.header, stamp_ns=frame.header.stamp_ns + tolerance_ns + 1)
    st.depth("front", late)
    assert st.take_round() == 1
    det = st.last("front")
    assert len(det.boxes) == 2 and det.boxes.columns == {} and "depth" not in det.timing_ms
    assert st.count("depth_unpaired") == st.count("depth_unpaired", "front") == 1
    assert st.count("depth_paired") == 0
    # Another, with nothing on the depth key at all.
    st.frame("front")
    assert st.take_round() == 1
    assert st.count("depth_unpaired", "front") == 2


def test_holes_make_a_box_unknown_never_a_made_up_number(st: Station) -> None:
    frame = st.frame("front")
    st.depth("front", frame.header, holes=(slice(None), slice(SIDE // 2, None)))  # right: none
    assert st.take_round() == 1
    det = st.last("front")
    left, right = np.argsort(det.boxes.xyxy[:, 0])
    for name in COLUMNS:
        assert math.isnan(float(det.boxes.columns[name][right])), name
        assert math.isfinite(float(det.boxes.columns[name][left])), name


def test_a_depth_image_of_another_size_gets_the_boxes_scaled(st: Station) -> None:
    frame = st.frame("front")
    depth = st.depth("front", frame.header, size=SIDE * 2)  # twice the colour frame's
    assert st.take_round() == 1
    det = st.last("front")
    i = int(np.argmin(det.boxes.xyxy[:, 0]))
    assert float(det.boxes.columns["z_m"][i]) == pytest.approx(METRES, abs=0.01)
    assert centre_back_projected(det, i, depth) == pytest.approx((8.0, 16.0), abs=0.5)


def test_garbage_on_the_depth_key_is_counted_and_the_next_depth_frame_pairs(
    st: Station,
) -> None:
    frame = st.frame("front")
    key = st.camera.keys.depth("front")
    st.put(key, b"\x00garbage")
    wrong = flat_depth(frame.header, 4, 4, METRES).encode().replace(b"16UC1", b"99XX9")
    st.put(key, wrong)
    assert st.count("bad_input") == st.count("bad_input", "front") == 2
    assert st.count("bad_input.depth") == 2
    st.depth("front", frame.header)
    assert st.take_round() == 1
    assert set(st.last("front").boxes.columns) == set(COLUMNS)
    assert st.count("depth_in", "front") == 3 and st.count("depth_paired", "front") == 1


def test_a_depth_image_over_max_frame_pixels_is_bad_input(model: Path) -> None:
    config = cameras_config(CAMERAS, max_batch=2, model=str(model))
    detector = Detector.open(model, settings=config.detector, max_batch=2)
    st = Station(detector, model=str(model), max_frame_pixels=SIDE * SIDE)
    frame = st.frame("front")
    st.depth("front", frame.header, size=SIDE * 2)
    assert st.count("bad_input", "front") == 1
    assert st.take_round() == 1
    assert st.count("depth_unpaired", "front") == 1


def test_depth_follows_the_announcement_and_the_serving(st: Station) -> None:
    st.depth("front", st.frame("front").header)
    assert st.count("depth_in", "front") == 1  # subscribed as the camera was announced
    st.take_round()
    # The source stops announcing depth: the subscription goes, its frames are 2D, uncounted.
    st.source.announce("front", depth=False)
    st.settle()
    frame = st.frame("front")
    st.depth("front", frame.header)
    assert st.take_round() == 1
    assert st.last("front").boxes.columns == {}
    assert st.count("depth_in") == 1 and st.count("depth_unpaired") == 0
    # Depth again: paired again.
    st.source.announce("front", depth=True)
    st.settle()
    frame = st.frame("front")
    st.depth("front", frame.header)
    assert st.take_round() == 1
    assert set(st.last("front").boxes.columns) == set(COLUMNS)
    assert st.count("depth_in", "front") == 2
    # The camera goes: so does its depth.
    st.source.withdraw("front")
    st.settle()
    st.depth("front", frame.header)
    assert st.count("depth_in", "front") == 2
    assert not st.handlers.depth.has_depth("front")


def test_a_worker_serving_two_robots_may_read_their_depth_and_put_none() -> None:
    """Under the secure profile's rules (stack/access.py from the detector's contract), a GPU
    box's worker serving robots 1 and 2 may subscribe to each one's depth images (and another
    robot's it may not); it may put none."""
    robot1, robot2, robot3 = Keys("robot1"), Keys("robot2"), Keys("robot3")
    acl = access_control(
        Keys("pool"), {"front": "camera"}, "certificate", workers=("detector_gpu",),
        prefixes=(robot1.prefix, robot2.prefix),
    )  # fmt: skip
    hub = MemoryHub(acl, names=principal_names("pool"))
    worker = hub.join("detector_gpu", principal="detector_gpu")
    for robot in (robot1, robot2, robot3):
        worker.subscribe(robot.all_depths(), lambda _: None)
        worker.subscribe(robot.depth("front"), lambda _: None)
        worker.publisher(robot.depth("front"), QoS.SENSOR).put(b"d")
    denied = {(kind, key) for who, kind, key in hub.denied if who == "detector_gpu"}
    assert denied == {
        *(("put", r.depth("front")) for r in (robot1, robot2, robot3)),
        ("declare_subscriber", robot3.all_depths()),
        ("declare_subscriber", robot3.depth("front")),
    }
