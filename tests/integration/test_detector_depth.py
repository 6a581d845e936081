"""The detector's depth stage in the real service (``python -m services.detector serve``, the
real default model), fed by this test's own Zenoh session as a depth camera's source would
be: the camera announced with ``depth=True`` (CameraAnnouncements), a real photo on its frame
key and, with the same header, a depth frame reading 2.5 m everywhere but a corner of holes.

One detector serves every check in turn (each only reads what came back): a frame with no
depth gets 2D detections and is counted ``depth_unpaired``; a frame with its depth gets
detections whose every row has the depth columns, 2.5 m deep, the 3D centre back-projecting to
the box's centre; garbage on the depth key is counted as bad input and the detector keeps
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
from services.camera.contract import CameraSettings
from tests.integration.conftest import wait_for
from tests.integration.test_detector_cameras import Detector, serve  # noqa: F401 (a fixture)
from tests.unit.detector.depthimage import flat_depth
from tests.unit.detector.headers import camera_header

pytestmark = pytest.mark.integration

METRES = 2.5
SIZE = (320, 320)  # the colour frame's (the astronaut, resized)
DEPTH_SIDE = 160  # the depth image's: half the colour frame's, so boxes are scaled
HOLES = (slice(0, 40), slice(0, 40))  # a corner with no reading
#: How far a 3D centre may back-project from its box's centre, as a share of the box's side.
CENTRE_SLACK = 0.03
WAIT_S = 60.0  # a round of the 640 model on a loaded 2-core machine is well under a second


class DepthCamera:
    """A camera with depth as the test plays it: announced with depth, one photo sent with a
    fresh header each time, with or without its depth frame."""

    def __init__(self, det: Detector) -> None:
        self.det = det
        self.photo = cv2.resize(load_sample("astronaut"), SIZE)
        self.announcements = CameraAnnouncements(ZenohBus(det.hub), det.keys, "camera")
        front = CameraSettings(rate_hz=10.0, frame_id="front_optical", mount_height_m=0.5)
        self.announcements.announce("front", front, width=SIZE[0], height=SIZE[1], depth=True)
        self.frames = Publisher(det.hub, det.keys.frame("front"), QoS.SENSOR)
        self.depths = Publisher(det.hub, det.keys.depth("front"), QoS.SENSOR)
        self.sent: dict[int, Header] = {}

    def header(self) -> Header:
        h = camera_header("front", len(self.sent) + 1)
        self.sent[h.seq] = h
        return h

    def answer(self, seqs: set[int]) -> Detections | None:
        """The detections of one of the frames ``seqs``, once back."""
        for d in self.det.detections("front"):
            if d.header.seq in seqs:
                assert d.header == self.sent[d.header.seq]
                return d
        return None

    def until_answered(self) -> Detections:
        """Send a frame, without depth, every poll until one comes back (a frame sent before
        the detector's subscription reaches the router is lost)."""
        seqs: set[int] = set()

        def answered() -> Detections | None:
            h = self.header()
            self.frames.put(image_to_frame(self.photo, h).encode())
            seqs.add(h.seq)
            return self.answer(seqs)

        return wait_for(answered, WAIT_S, lambda: f"detections of front:\n{self.det.log()}", 0.3)

    def with_depth(self) -> Detections:
        """A frame and its depth frame, the depth frame first and heard (``depth_in``) before
        the frame is sent: on a loaded machine the depth subscription's thread may otherwise
        lag the frame's past the model's run, which the pairing does not wait for (2D,
        counted unpaired: a right answer, but not the one this test checks)."""
        h = self.header()
        heard = self.det.counter("depth_in.front")
        depth = flat_depth(h, DEPTH_SIDE, DEPTH_SIDE, METRES, holes=HOLES).encode()

        def depth_heard() -> bool:
            self.depths.put(depth)  # again when the first was lost: the same stamp
            return self.det.counter("depth_in.front") > heard

        wait_for(depth_heard, WAIT_S, lambda: f"depth_in counted:\n{self.det.log()}", 0.3)
        self.frames.put(image_to_frame(self.photo, h).encode())
        return wait_for(
            lambda: self.answer({h.seq}),
            WAIT_S,
            lambda: f"detections of frame {h.seq}:\n{self.det.log()}",
        )


def test_a_photo_with_depth_gets_3d_detections_without_it_2d_and_garbage_is_dropped(
    serve: Any,  # noqa: F811 (the fixture)
) -> None:
    det: Detector = serve(
        {"front": {"frame_id": "front_optical"}},
        # A frame waits for its depth frame's count (counters every 0.2 s) before it is sent.
        detector={"counters_period_s": 0.2, "max_frame_age_s": 30.0},
    )
    cam = DepthCamera(det)
    wait_for(
        lambda: det.counter("serving.front") == 1 and "depth_in.front" in det.counters[-1],
        WAIT_S,
        lambda: f"the detector to serve front and its depth:\n{det.log()}",
    )

    # No depth: 2D detections, counted unpaired.
    without = cam.until_answered()
    assert "person" in without.class_names
    assert without.boxes.columns == {} and "depth" not in without.timing_ms
    wait_for(
        lambda: det.counter("depth_unpaired.front") >= 1,
        WAIT_S,
        lambda: f"depth_unpaired counted:\n{det.log()}",
    )

    # With depth: every row has every column, 2.5 m deep or unknown (the corner's holes).
    with_depth = cam.with_depth()
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
        x1, y1, x2, y2 = (float(b) for b in boxes.xyxy[i])
        # The object's centre, not the box's: the method's centre is that of the valid
        # pixels it takes for the object (sampled on a grid; the holes take some away).
        near = 2.0 + CENTRE_SLACK * max(x2 - x1, y2 - y1)
        assert (u, v) == pytest.approx(((x1 + x2) / 2, (y1 + y2) / 2), abs=near)
    person = with_depth.class_names.index("person")
    assert math.isfinite(float(boxes.columns["distance_m"][person]))
    assert known >= 1
    wait_for(
        lambda: det.counter("depth_paired.front") >= 1,
        WAIT_S,
        lambda: f"depth_paired counted:\n{det.log()}",
    )

    # Garbage on the depth key: counted, dropped; the detector pairs the next frames.
    for payload in (b"\x00garbage", np.zeros(64, np.uint8).tobytes()):
        cam.depths.put(payload)
    wait_for(
        lambda: det.counter("bad_input.front") >= 2 and det.counter("bad_input.depth") >= 2,
        WAIT_S,
        lambda: f"bad depth counted:\n{det.log()}",
    )
    again = cam.with_depth()
    assert set(again.boxes.columns) == set(COLUMNS)
    assert det.proc.poll() is None
