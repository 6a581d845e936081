"""The live view's conversions, decoded as Foxglove would: protobuf from the advertised schema."""

from __future__ import annotations

import base64
import math
from typing import Any

import cv2
import numpy as np
import pytest
from foxglove.messages import (
    CompressedImage,
    FrameTransforms,
    ImageAnnotations,
    LaserScan,
    SceneUpdate,
)

from common.boxes import Boxes
from common.errors import ImageError
from common.messages import Detections, Frame, GroundTruth, Header
from common.messages import LaserScan as StackScan
from services.viewer import convert, scene
from tests.foxglove_client import decode_protobuf

HEADER = Header(stamp_ns=1_700_000_000_250_000_000, frame_id="camera", seq=7, source="sim")


def _decode(msg: Any) -> dict[str, Any]:
    schema = type(msg).get_schema()
    return decode_protobuf(schema.name, schema.data, msg.encode())


def _frame(width: int = 640, height: int = 480) -> Frame:
    image = np.zeros((height, width, 3), np.uint8)
    image[:, : width // 2] = (0, 0, 255)  # left half red, so that a flip would show
    return Frame(header=HEADER, encoding="bgr8", width=width, height=height, data=image.tobytes())


def test_image_is_a_jpeg_scaled_to_the_width_limit() -> None:
    msg = _decode(convert.compressed_image(_frame(), jpeg_quality=80, max_width=320))
    assert msg["format"] == "jpeg" and msg["frameId"] == "camera"
    assert msg["timestamp"] == "2023-11-14T22:13:20.250Z"
    image = cv2.imdecode(np.frombuffer(base64.b64decode(msg["data"]), np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (240, 320, 3)
    assert image[120, 40, 2] > 200 and image[120, 280, 2] < 50
    kept = _decode(convert.compressed_image(_frame(), jpeg_quality=80, max_width=0))
    shape = cv2.imdecode(np.frombuffer(base64.b64decode(kept["data"]), np.uint8), 1).shape
    assert shape == (480, 640, 3)


def test_a_corrupt_jpeg_frame_is_an_image_error() -> None:
    bad = Frame(header=HEADER, encoding="jpeg", width=64, height=64, data=b"\xff\xd8garbage")
    with pytest.raises(ImageError):
        convert.compressed_image(bad, 80, 0)


def _detections() -> Detections:
    return Detections(
        header=HEADER,
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.array([[100, 40, 300, 440], [400, 200, 600, 400]], np.float32),
            scores=np.array([0.9, 0.5], np.float32),
            class_ids=np.array([0, 56], np.int32),
            track_ids=np.array([5, -1], np.int32),
        ),
        class_names=("person", "chair"),
    )


def test_annotations_scale_the_boxes_and_mark_the_locked_target() -> None:
    msg = _decode(convert.image_annotations(_detections(), 320, 240, locked_track=5))
    person, chair = msg["points"]
    assert person["type"] == "LINE_LOOP"
    assert [(p["x"], p.get("y", 0.0)) for p in person["points"]] == [
        (50.0, 20.0), (150.0, 20.0), (150.0, 220.0), (50.0, 220.0)
    ]  # fmt: skip
    assert person["thickness"] == convert.LOCKED_THICKNESS_PX
    assert person["outlineColor"]["r"] == pytest.approx(1.0) and "g" in person["outlineColor"]
    assert chair["thickness"] == convert.BOX_THICKNESS_PX
    assert [t["text"] for t in msg["texts"]] == ["LOCKED person 0.90 #5", "chair 0.50"]
    unlocked = _decode(convert.image_annotations(_detections(), 640, 480, locked_track=-1))
    assert [t["text"] for t in unlocked["texts"]] == ["person 0.90 #5", "chair 0.50"]


def test_scan_is_in_the_robot_frame_with_its_angles() -> None:
    scan = StackScan(
        header=HEADER, angle_min=-math.pi / 2, angle_increment=math.pi / 2, range_min=0.05,
        range_max=10.0, ranges=np.array([1.0, np.inf, 2.5], np.float32),
    )  # fmt: skip
    msg = _decode(convert.laser_scan(scan))
    assert msg["frameId"] == "base_link"
    assert msg["startAngle"] == pytest.approx(-math.pi / 2)
    assert msg["endAngle"] == pytest.approx(math.pi / 2)
    assert msg["ranges"] == [1.0, "Infinity", 2.5]


def test_metrics_keep_the_plottable_figures() -> None:
    answer: Any = {
        "fps": 4.5, "detections_per_frame": 1.0, "dropped_frames": 3, "drop_rate": 0.1,
        "counters": {"detector.bad_input": 2, "controller.bad_input": 1, "sim.frames_out": 9},
        "latency_ms": {"inference": {"p50": 120.0, "p95": 150.0}}, "timeline": {"t": [1.0]},
    }  # fmt: skip
    out = convert.metrics_json(answer)
    assert out["bad_input"] == 3 and out["latency_ms"]["inference"]["p50"] == 120.0
    assert "timeline" not in out


def _truth(x: float, y: float, theta: float) -> GroundTruth:
    return GroundTruth(
        header=HEADER, sim_time_s=1.0, robot=(x, y, theta),
        targets_xy=np.array([[4.0, 0.5]]), target_names=("person",), target_ids=("alice",),
        obstacles=np.array([[2.0, -1.0, 0.3], [3.0, 1.0, 0.2]]),
    )  # fmt: skip


def test_transform_places_the_robot_in_the_world() -> None:
    (tf,) = _decode(scene.transforms(_truth(1.0, 2.0, math.pi / 2)))["transforms"]
    assert (tf["parentFrameId"], tf["childFrameId"]) == ("world", "base_link")
    assert tf["translation"] == {"x": 1.0, "y": 2.0}  # protobuf leaves out zeros
    assert tf["rotation"]["z"] == pytest.approx(math.sqrt(0.5))
    assert tf["rotation"]["w"] == pytest.approx(math.sqrt(0.5))


def test_scene_has_robot_targets_obstacles_and_path() -> None:
    trail = scene.PathTrail(size=3)
    for x in (0.0, 0.001, 0.5, 1.0, 1.5):  # the second is too close to count
        trail.add(x, 0.0)
    assert trail.points() == [(0.5, 0.0), (1.0, 0.0), (1.5, 0.0)]
    msg = _decode(scene.scene(_truth(1.5, 0.0, 0.0), trail.points()))
    robot, world = msg["entities"]
    assert robot["frameId"] == "base_link" and robot["frameLocked"] is True
    assert world["frameId"] == "world"
    assert len(world["cylinders"]) == 3  # one target, two obstacles
    assert world["cylinders"][1]["size"]["x"] == pytest.approx(0.6)
    assert world["texts"][0]["text"] == "person alice"
    assert [p["x"] for p in world["lines"][0]["points"]] == [0.5, 1.0, 1.5]


def test_the_message_types_are_foxgloves_own() -> None:
    names = {t.get_schema().name for t in (CompressedImage, ImageAnnotations, LaserScan,
                                           FrameTransforms, SceneUpdate)}  # fmt: skip
    assert names == {
        "foxglove.CompressedImage", "foxglove.ImageAnnotations", "foxglove.LaserScan",
        "foxglove.FrameTransforms", "foxglove.SceneUpdate",
    }  # fmt: skip


def test_labels_stay_inside_the_image() -> None:
    from services.viewer.convert import LABEL_FONT_PX, label_position

    # Room above the box: the text's bottom-left corner on the box's top edge.
    assert label_position(100.0, 50.0, "person 0.90", 640) == (100.0, 50.0)
    # A box touching the image's top: the text inside the box, not above the image.
    assert label_position(100.0, 0.0, "person 0.90 #1", 640)[1] == LABEL_FONT_PX
    # A box at the right edge: the label moved left, whole.
    x, _ = label_position(630.0, 50.0, "person 0.90", 640)
    assert x < 630.0 and x + 0.6 * LABEL_FONT_PX * len("person 0.90") <= 640.0
