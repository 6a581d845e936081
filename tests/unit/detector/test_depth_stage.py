"""The depth stage's wait for a depth frame still on its way (services/detector/
depth_stage.py's :class:`DepthStage`, ``detector.depth_wait_ms``), with a real Tally and a
thread of the test's own as the depth subscription: a frame waits for a depth frame that may
still come, and only then; a depth stream gone quiet costs one wait, not one per frame."""

from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np
import pytest

from common.boxes import Boxes
from common.messages import Header
from common.node import Tally
from perception.depth import COLUMNS
from services.detector import depth_stage
from services.detector.depth_stage import DepthStage
from stack.config import Config
from tests.polling import wait_for
from tests.unit.detector.depthimage import flat_depth
from tests.unit.detector.headers import camera_header

SIDE = 64
BOXES = Boxes(
    xyxy=np.array([[16, 16, 48, 48]], np.float32),
    scores=np.array([0.9], np.float32),
    class_ids=np.array([0], np.int32),
)


def stage(wait_ms: float = 10.0) -> DepthStage:
    config = Config()
    config = replace(config, detector=replace(config.detector, depth_wait_ms=wait_ms))
    s = DepthStage(config.detector, Tally("detector", config))
    s.add_camera("front", "stack/camera/front/depth")
    return s


def at(header: Header, ms: int) -> Header:
    return replace(header, stamp_ns=header.stamp_ns + ms * 1_000_000)


def depth(s: DepthStage, header: Header) -> None:
    s.on_depth("front", flat_depth(header, SIDE, SIDE, 2.0).encode())


def detections(s: DepthStage, header: Header) -> Boxes:
    """The frame of ``header`` arrives, is taken by a round, and its detections are built."""
    s.colour("front", header)
    s.hold("front", header)
    boxes, _ = s.measure("front", header, (SIDE, SIDE), BOXES)
    return boxes


def test_a_frame_waits_for_its_depth_frame_still_on_its_way() -> None:
    s = stage()
    s.wait_s = 60.0  # however loaded the machine: the depth frame comes while it waits
    h = camera_header("front", 1)
    depth(s, at(h, -100))  # the stream is alive; this frame's depth is not here yet
    sender = threading.Thread(
        target=lambda: (wait_for(lambda: s.waiting == 1, 30, "the wait"), depth(s, h))
    )
    sender.start()
    boxes = detections(s, h)
    sender.join()
    assert set(boxes.columns) == set(COLUMNS) and s.waits == 1
    assert s.tally.counters.get("depth_paired") == 1


def test_no_wait_when_its_depth_frame_cannot_come_any_more() -> None:
    s = stage(wait_ms=200.0)
    h = camera_header("front", 1)
    depth(s, at(h, 100))  # a later one came: depth comes in stamp order, this one is lost
    assert detections(s, h).columns == {}
    assert s.waits == 0 and s.tally.counters.get("depth_unpaired") == 1


def test_a_depth_stream_gone_quiet_costs_one_wait_until_a_frame_pairs_again() -> None:
    s = stage(wait_ms=5.0)
    h = camera_header("front", 1)
    depth(s, at(h, -100))
    for n in range(3):
        assert detections(s, at(h, 50 * n)).columns == {}
    assert s.waits == 1  # the first frame waited; the next two did not
    depth(s, at(h, 200))
    assert set(detections(s, at(h, 200)).columns) == set(COLUMNS)
    assert detections(s, at(h, 250)).columns == {}  # it paired last: this one waits again
    assert s.waits == 2


def test_a_zero_wait_never_waits() -> None:
    s = stage(wait_ms=0.0)
    h = camera_header("front", 1)
    depth(s, at(h, -100))
    assert detections(s, h).columns == {}
    assert s.tally.counters.get("depth_unpaired") == 1


def test_a_depth_stage_that_raises_gives_2d_detections_logged_and_counted(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A defect in the method (here: the measure raising) must not stop the detector's round:
    the frame's detections go out without depth, and the failure is counted."""

    def broken(*_: object) -> None:
        raise FloatingPointError("a defect")

    monkeypatch.setattr(depth_stage, "measure_depth", broken)
    s = stage()
    h = camera_header("front", 1)
    depth(s, h)
    boxes = detections(s, h)
    assert boxes.columns == {} and len(boxes) == 1
    assert s.tally.counters.get("depth_failed") == 1
    assert s.tally.counters.get("depth_failed.front") == 1
