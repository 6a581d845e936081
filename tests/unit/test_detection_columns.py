"""A column added where the detector builds its message reaches every consumer's output by
name, through the converters as they are: none of them names a column.

The detections go the detector's way (its selection, its tracker's ids, the message), over the
wire (encode, decode), then into each form the stack turns them into: the recorder's MCAP (JSON
on the stack key, read back by the run comparison), the viewer's Foxglove annotations (decoded
as Foxglove does), the ROS 2 bridge's Detection2DArray (vision_msgs has no slot: the columns are
left out, the rest converts) and the debug image's labels.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from common.annotate import annotate
from common.boxes import Boxes
from common.messages import Detections, Header
from perception.postprocess import select
from perception.tracker import Tracker
from rosmsg.convert import DETECTION_2D_ARRAY, cdr_decode, detections_to_ros
from rosmsg.distro import RosDistro
from services.recorder.channels import JSON_SCHEMA, Translator
from services.recorder.contract import RecorderSettings
from services.recorder.writer import McapFile
from services.ros2.contract import Ros2Settings
from services.viewer.convert import image_annotations
from tests.foxglove_client import decode_protobuf
from tools.compare.runs import load_run

HEADER = Header(stamp_ns=1_700_000_000_250_000_000, frame_id="camera", seq=7, source="sim")
KEY = "stack/detector/front/detections"


def _detector_message() -> Detections:
    """What the detector would publish with a feature that adds three columns: the candidates
    carry them, NMS drops the second (it overlaps the first, which scores higher), the tracker
    numbers the rest."""
    candidates = Boxes(
        xyxy=np.array([[10, 20, 110, 220], [12, 20, 110, 221], [300, 300, 400, 350]], np.float32),
        scores=np.array([0.9, 0.6, 0.5], np.float32),
        class_ids=np.array([0, 0, 2], np.int32),
        columns={
            "distance_m": np.array([2.5, 9.0, np.nan], np.float32),  # NaN: unknown
            "lane": np.array([1, 5, -2], np.int32),
            "occluded": np.array([False, True, True]),
        },
    )
    kept = select(candidates, iou=0.5, max_det=10, apply_nms=True)
    track_ids = Tracker().update(kept, 1.0)
    return Detections(
        header=HEADER,
        image_width=640,
        image_height=480,
        boxes=kept.with_track_ids(track_ids),
        class_names=("person", "car"),
    )


def _received() -> Detections:
    return Detections.decode(_detector_message().encode())  # as every subscriber gets it


def test_the_columns_survive_the_detector_and_the_wire() -> None:
    dets = _received()
    assert dets.boxes.track_ids is not None and len(dets) == 2
    cols = dets.boxes.columns
    assert cols["distance_m"].dtype == np.float32 and cols["lane"].tolist() == [1, -2]
    assert cols["distance_m"][0] == 2.5 and np.isnan(cols["distance_m"][1])
    assert cols["occluded"].tolist() == [False, True]


def test_the_recording_holds_every_column_by_name_and_reads_back(tmp_path: Path) -> None:
    dets = _received()
    entries = Translator(Ros2Settings(), "front").entries(KEY, dets)
    (js,) = [e for e in entries if e.channel.message_encoding == "json"]
    body = json.loads(js.data)
    assert body["columns"] == {
        "distance_m": [2.5, None],  # JSON has no NaN
        "lane": [1, -2],
        "occluded": [False, True],
    }
    schema = json.loads(dict(js.channel.metadata)[JSON_SCHEMA])
    assert schema["properties"]["columns"]["type"] == "object"
    out = McapFile(tmp_path / "run.mcap", RecorderSettings())
    for entry in entries:
        out.add(entry, HEADER.stamp_ns)
    out.close()
    back = load_run(tmp_path / "run.mcap").detections[("front", 7)].boxes.columns
    assert list(back) == ["distance_m", "lane", "occluded"]
    assert back["distance_m"][0] == 2.5 and np.isnan(back["distance_m"][1])
    assert back["lane"].tolist() == [1, -2] and back["occluded"].tolist() == [False, True]


def test_the_viewer_labels_each_box_with_its_columns() -> None:
    marks = image_annotations(_received(), 320, 240, locked_track=-1)
    schema = type(marks).get_schema()
    texts = [t["text"] for t in decode_protobuf(schema.name, schema.data, marks.encode())["texts"]]
    assert texts[0].startswith("person 0.90 #") and texts[1].startswith("car 0.50 #")
    assert texts[0].endswith(" distance_m=2.5 lane=1 occluded=no")
    assert texts[1].endswith(" distance_m=nan lane=-2 occluded=yes")


def test_the_ros2_bridge_converts_the_rest_and_leaves_the_columns_out() -> None:
    dets = _received()
    for with_columns in (dets, _without_columns(dets)):
        ros = detections_to_ros(RosDistro.JAZZY, with_columns)
        assert [d.results[0].hypothesis.class_id for d in ros.detections] == ["person", "car"]
    recorded = Translator(Ros2Settings(), "front").entries(KEY, dets)
    (cdr,) = [e for e in recorded if e.channel.message_encoding == "cdr"]
    plain = Translator(Ros2Settings(), "front").entries(KEY, _without_columns(dets))
    (cdr_plain,) = [e for e in plain if e.channel.message_encoding == "cdr"]
    assert cdr.data == cdr_plain.data  # vision_msgs has no slot for them (docs/ros2.md)
    assert len(cdr_decode(RosDistro.JAZZY, DETECTION_2D_ARRAY, cdr.data).detections) == 2


def test_the_debug_image_labels_show_the_columns() -> None:
    dets = _received()
    image = np.full((480, 640, 3), 255, np.uint8)
    drawn = annotate(image, dets.boxes, dets.class_names)
    plain = annotate(image, _without_columns(dets).boxes, dets.class_names)
    # The labels are longer: more of the image differs from the blank one.
    assert (drawn != image).any(axis=2).sum() > (plain != image).any(axis=2).sum()


def _without_columns(dets: Detections) -> Detections:
    return replace(dets, boxes=replace(dets.boxes, columns={}))
