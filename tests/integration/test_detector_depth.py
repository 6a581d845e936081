"""The detector's depth stage in the real service (``python -m services.detector serve``, the
real default model), fed by this test's own Zenoh session as a depth camera's source would
be: the camera announced with ``depth=True`` (CameraAnnouncements), a real photo on its frame
key and, with the same header, a depth frame reading 2.5 m everywhere but a corner of holes.

One detector serves every check in turn (each only reads what came back): a frame with its
depth gets detections whose every row has the depth columns, 2.5 m deep, the 3D centre
back-projecting to the box's centre; a frame with no depth gets 2D detections and is counted
``depth_unpaired``; garbage on the depth key is counted as bad input and the detector keeps
pairing. The pairing rules themselves are unit-tested (tests/unit/detector/
test_depth_pairing.py, test_depth_bus.py)."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
import pytest

from common.camera_announce import CameraAnnouncements
from common.frames import image_to_frame
from common.images import load_sample
from common.messages import Detections, Header
from common.zenoh_bus import Publisher, QoS, ZenohBus
from perception.depth import COLUMNS
from tests.integration.conftest import wait_for
from tests.integration.test_detector_cameras import Detector, serve  # noqa: F401 (a fixture)
from tests.unit.detector.depthimage import flat_depth
from tests.unit.detector.headers import camera_header

pytestmark = pytest.mark.integration

METRES = 2.5
SIZE = (320, 320)  # the colour frame's (the astronaut, resized)
DEPTH_SIDE = 160  # the depth image's: half the colour frame's, so boxes are scaled
HOLES = (slice(0, 40), slice(0, 40))  # a corner with no reading
WAIT_S = 60.0  # a round of the 640 model on a loaded 2-core machine is well under a second


class DepthCamera:
    """A camera with depth as the test plays it: announced with depth, one photo sent with a
    fresh header each time, with or without its depth frame."""

    def __init__(self, det: Detector) -> None:
        self.det = det
        self.photo = cv2.resize(load_sample("astronaut"), SIZE)
        self.announcements = CameraAnnouncements(ZenohBus(det.hub), det.keys, "camera")
        self.announcements.announce(
            "front", rate_hz=10.0, mount_yaw_deg=0.0, hfov_deg=60.0, frame_id="front_optical",
            width=SIZE[0], height=SIZE[1], depth=True, mount_height_m=0.5,
        )  # fmt: skip
        self.frames = Publisher(det.hub, det.keys.frame("front"), QoS.SENSOR)
        self.depths = Publisher(det.hub, det.keys.depth("front"), QoS.SENSOR)
        self.sent: dict[int, Header] = {}

    def send(self, *, depth: bool) -> Header:
        h = camera_header("front", len(self.sent) + 1)
        self.sent[h.seq] = h
        if depth:  # first, as often as not: the pairing takes either order
            self.depths.put(flat_depth(h, DEPTH_SIDE, DEPTH_SIDE, METRES, holes=HOLES).encode())
        self.frames.put(image_to_frame(self.photo, h).encode())
        return h

    def answer(self, seqs: set[int]) -> Detections | None:
        """The detections of one of the frames ``seqs``, once back."""
        for d in self.det.detections("front"):
            if d.header.seq in seqs:
                assert d.header == self.sent[d.header.seq]
                return d
        return None

    def until_answered(self, *, depth: bool) -> Detections:
        """Send (a frame every poll: a frame sent before the detector's subscriptions reach
        the router is lost) until one comes back."""
        seqs: set[int] = set()

        def answered() -> Detections | None:
            seqs.add(self.send(depth=depth).seq)
            return self.answer(seqs)

        return wait_for(answered, WAIT_S, lambda: f"detections of front:\n{self.det.log()}", 0.3)


def counted(det: Detector, name: str) -> int:
    return det.counter(name)


def test_a_photo_with_depth_gets_3d_detections_without_it_2d_and_garbage_is_dropped(
    serve: Any,  # noqa: F811 (the fixture)
) -> None:
    det: Detector = serve({"front": {"frame_id": "front_optical"}})
    cam = DepthCamera(det)
    wait_for(
        lambda: counted(det, "serving.front") == 1 and "depth_in.front" in det.counters[-1],
        WAIT_S,
        lambda: f"the detector to serve front and its depth:\n{det.log()}",
    )

    def depth_heard() -> bool:  # the depth subscription's route is through to the router
        cam.depths.put(flat_depth(camera_header("front", 0), DEPTH_SIDE, DEPTH_SIDE, 1.0).encode())
        return counted(det, "depth_in.front") >= 1

    wait_for(depth_heard, WAIT_S, lambda: f"depth_in counted:\n{det.log()}", 0.3)

    # With depth: every row has every column, 2.5 m deep or unknown (the corner's holes).
    with_depth = cam.until_answered(depth=True)
    boxes = with_depth.boxes
    assert "person" in with_depth.class_names and set(boxes.columns) == set(COLUMNS)
    assert "depth" in with_depth.timing_ms
    sx, sy = SIZE[0] / DEPTH_SIDE, SIZE[1] / DEPTH_SIDE
    fx = (DEPTH_SIDE / 2) / math.tan(math.radians(30))  # flat_depth's intrinsics
    known = 0
    for i in range(len(boxes)):
        row = {name: float(boxes.columns[name][i]) for name in COLUMNS}
        if all(math.isnan(v) for v in row.values()):
            continue  # unknown: a box in the holes
        known += 1
        x, y, z = row["x_m"], row["y_m"], row["z_m"]
        assert z == pytest.approx(METRES, abs=0.02), row
        assert row["distance_m"] == pytest.approx(math.sqrt(x * x + y * y + z * z), rel=1e-4)
        u = (fx * x / z + DEPTH_SIDE / 2) * sx
        v = (fx * y / z + DEPTH_SIDE / 2) * sy
        x1, y1, x2, y2 = boxes.xyxy[i]
        assert (u, v) == pytest.approx(((x1 + x2) / 2, (y1 + y2) / 2), abs=1.0)
    person = with_depth.class_names.index("person")
    assert math.isfinite(float(boxes.columns["distance_m"][person]))
    assert known >= 1
    wait_for(
        lambda: counted(det, "depth_paired.front") >= 1,
        WAIT_S,
        lambda: f"depth_paired counted:\n{det.log()}",
    )

    # No depth: 2D detections, counted unpaired.
    unpaired = counted(det, "depth_unpaired.front")
    without = cam.until_answered(depth=False)
    assert "person" in without.class_names
    assert without.boxes.columns == {} and "depth" not in without.timing_ms
    wait_for(
        lambda: counted(det, "depth_unpaired.front") > unpaired,
        WAIT_S,
        lambda: f"depth_unpaired counted:\n{det.log()}",
    )

    # Garbage on the depth key: counted, dropped; the detector pairs the next frames.
    for payload in (b"\x00garbage", np.zeros(64, np.uint8).tobytes()):
        cam.depths.put(payload)
    wait_for(
        lambda: counted(det, "bad_input.front") >= 2 and counted(det, "bad_input.depth") >= 2,
        WAIT_S,
        lambda: f"bad depth counted:\n{det.log()}",
    )
    again = cam.until_answered(depth=True)
    assert set(again.boxes.columns) == set(COLUMNS)
    assert det.proc.poll() is None
