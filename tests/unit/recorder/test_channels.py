"""What a message becomes in a recording: ROS 2 schemas that rosbags parses back, CDR that
decodes to the same values, JSON with its schema in the channel's metadata."""

from __future__ import annotations

import json

import numpy as np
from rosbags.typesys import get_types_from_msg

from common.boxes import Boxes
from common.messages import ControllerStatus, Detections, Frame, Header, LaserScan, Twist
from rosmsg.convert import cdr_decode
from rosmsg.distro import RosDistro
from services.recorder.channels import (
    JSON_SCHEMA,
    STACK_MESSAGE,
    Translator,
    json_schema,
    ros2msg_schema,
    to_json,
)
from services.ros2.contract import Ros2Settings

HEADER = Header(stamp_ns=1_700_000_000_123_456_789, frame_id="camera", seq=7, source="sim")


def _detections() -> Detections:
    return Detections(
        header=HEADER,
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.array([[10, 20, 110, 220], [300, 300, 400, 350]], np.float32),
            scores=np.array([0.9, 0.5], np.float32),
            class_ids=np.array([0, 2], np.int32),
            track_ids=np.array([3, -1], np.int32),
        ),
        class_names=("person", "car"),
        timing_ms={"inference": 12.5},
        received_ns=HEADER.stamp_ns + 5_000_000,
        published_ns=HEADER.stamp_ns + 30_000_000,
    )


def test_the_ros2msg_schema_names_every_dependency_and_parses_back() -> None:
    text = ros2msg_schema(RosDistro.JAZZY, "vision_msgs/msg/Detection2DArray").decode()
    parts = text.split("=" * 80 + "\n")
    names = {p.split("\n", 1)[0].removeprefix("MSG: ") for p in parts[1:]}
    assert {"std_msgs/Header", "vision_msgs/Detection2D", "vision_msgs/BoundingBox2D",
            "builtin_interfaces/Time"} <= names  # fmt: skip
    types = get_types_from_msg(text, "vision_msgs/msg/Detection2DArray")
    assert "vision_msgs/msg/Detection2DArray" in types


def test_detections_are_cdr_on_the_bridge_topic_and_json_on_the_stack_key() -> None:
    ros2 = Ros2Settings()
    cdr, js = Translator(ros2, "front").entries("stack/detector/front/detections", _detections())
    assert (cdr.channel.topic, cdr.channel.message_encoding) == ("/detections", "cdr")
    assert cdr.channel.schema_name == "vision_msgs/msg/Detection2DArray"
    assert (cdr.sequence, cdr.publish_ns) == (7, HEADER.stamp_ns)
    ros = cdr_decode(RosDistro.JAZZY, cdr.channel.schema_name, cdr.data)
    assert [d.results[0].hypothesis.class_id for d in ros.detections] == ["person", "car"]
    assert ros.detections[0].bbox.size_x == 100.0
    assert (ros.header.stamp.sec, ros.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert js.channel.topic == "stack/detector/front/detections"
    meta = dict(js.channel.metadata)
    assert meta[STACK_MESSAGE] == "Detections" and js.channel.schema_name == ""
    body = json.loads(js.data)
    assert body["header"]["seq"] == 7 and body["timing_ms"] == {"inference": 12.5}
    assert body["xyxy"][1] == [300.0, 300.0, 400.0, 350.0] and body["track_ids"] == [3, -1]
    assert set(json.loads(meta[JSON_SCHEMA])["properties"]) == set(body)


def test_frames_scans_and_commands_take_their_ros_types() -> None:
    t = Translator(Ros2Settings(image_topic="/cam/image"), "front")
    raw = Frame(header=HEADER, encoding="bgr8", width=4, height=2, data=bytes(range(24)))
    (image,) = t.entries("k", raw)
    assert image.channel.topic == "/cam/image"
    assert image.channel.schema_name == "sensor_msgs/msg/Image"
    assert bytes(cdr_decode(RosDistro.JAZZY, "sensor_msgs/msg/Image", image.data).data) == raw.data
    jpeg = Frame(header=HEADER, encoding="jpeg", width=4, height=2, data=b"\xff\xd8not-checked")
    (compressed,) = t.entries("k", jpeg)
    assert compressed.channel.topic == "/cam/image/compressed"
    scan = LaserScan(header=HEADER, angle_min=-1.0, angle_increment=0.5, range_min=0.1,
                     range_max=10.0, ranges=np.array([1.0, np.inf, 2.0], np.float32))  # fmt: skip
    (ros_scan,) = t.entries("k", scan)
    assert ros_scan.channel.schema_name == "sensor_msgs/msg/LaserScan"
    twist = Twist(header=HEADER, linear=(0.3, 0, 0), angular=(0, 0, -0.2), input_stamp_ns=5)
    stamped, js = t.entries("stack/controller/cmd_vel", twist)
    ros = cdr_decode(RosDistro.JAZZY, "geometry_msgs/msg/TwistStamped", stamped.data)
    assert (ros.twist.linear.x, ros.twist.angular.z) == (0.3, -0.2)
    assert json.loads(js.data)["input_stamp_ns"] == 5
    # One channel per topic and type, reused for every message.
    assert t.entries("k", raw)[0].channel is image.channel


def test_messages_without_a_ros_type_are_json_only() -> None:
    status = ControllerStatus(header=HEADER, mode="follow", target="person", state="following")
    (entry,) = Translator(Ros2Settings(), "front").entries("stack/controller/status", status)
    assert entry.channel.message_encoding == "json"
    assert json.loads(entry.data)["state"] == "following"


def test_json_has_no_nan_and_the_schema_types_fields() -> None:
    scan = LaserScan(header=HEADER, angle_min=0.0, angle_increment=0.1, range_min=0.0,
                     range_max=5.0, ranges=np.array([np.nan, 1.0], np.float32))  # fmt: skip
    assert json.loads(to_json(scan))["ranges"] == [None, 1.0]
    schema = json_schema(Detections)
    assert schema["properties"]["header"]["properties"]["seq"] == {"type": "integer"}
    assert schema["properties"]["track_ids"]["anyOf"][-1] == {"type": "null"}


def test_each_cameras_frames_and_detections_go_on_its_own_ros_topics() -> None:
    t = Translator(Ros2Settings(), "front")
    raw = Frame(header=HEADER, encoding="bgr8", width=4, height=2, data=bytes(range(24)))
    jpeg = Frame(header=HEADER, encoding="jpeg", width=4, height=2, data=b"\xff\xd8not-checked")
    written = [
        [e.channel.topic for e in t.entries(key, msg)]
        for key, msg in (
            ("test/x/camera/front/frame", raw),  # the first camera: as with one camera
            ("test/x/camera/rear/frame", raw),
            ("test/x/camera/rear/frame", jpeg),
            ("test/x/detector/front/detections", _detections()),
            ("test/x/detector/rear/detections", _detections()),
        )
    ]
    assert written == [
        ["/camera/rgb/image_raw"],
        ["/rear/camera/rgb/image_raw"],
        ["/rear/camera/rgb/image_raw/compressed"],
        ["/detections", "test/x/detector/front/detections"],
        ["/rear/detections", "test/x/detector/rear/detections"],
    ]


def test_a_virtual_scan_is_recorded_on_its_own_topic_and_never_played_as_the_laser() -> None:
    # Issue 40: each depth camera's virtual scan is published on <prefix>/scan/virtual/<camera>;
    # the recording keeps it beside the laser's scan, not on it, and a replay (which puts
    # every scan it plays on the laser's key) leaves it out.
    from mcap.records import Channel as McapChannel
    from mcap.records import Message as McapMessage
    from mcap.records import Schema as McapSchema

    from services.recorder.channels import VIRTUAL_SCAN
    from services.recorder.reading import Input, Record, input_kind

    t = Translator(Ros2Settings(), "front")
    scan = LaserScan(header=HEADER, angle_min=-1.0, angle_increment=0.5, range_min=0.0,
                     range_max=10.0, ranges=np.array([1.0, np.nan, 2.0], np.float32))  # fmt: skip
    (laser,) = t.entries("stack/scan", scan)
    (virtual,) = t.entries("stack/scan/virtual/front", scan)
    assert laser.channel.topic == "/scan" and VIRTUAL_SCAN not in dict(laser.channel.metadata)
    assert virtual.channel.topic == "/scan/virtual/front"
    assert dict(virtual.channel.metadata)[VIRTUAL_SCAN] == "front"
    assert virtual.channel.schema_name == "sensor_msgs/msg/LaserScan"

    def record(entry_channel: object, metadata: dict[str, str]) -> Record:
        schema = McapSchema(id=1, name="sensor_msgs/msg/LaserScan", encoding="ros2msg", data=b"")
        channel = McapChannel(id=1, topic=entry_channel.topic, message_encoding="cdr",
                              metadata=metadata, schema_id=1)  # fmt: skip
        message = McapMessage(channel_id=1, log_time=0, data=b"", publish_time=0, sequence=0)
        return Record(schema, channel, message)

    assert input_kind(record(laser.channel, dict(laser.channel.metadata))) is Input.SCAN
    assert input_kind(record(virtual.channel, dict(virtual.channel.metadata))) is None


def test_the_depth_memorys_scans_are_recorded_on_their_topics_and_never_played() -> None:
    from mcap.records import Channel as McapChannel
    from mcap.records import Message as McapMessage
    from mcap.records import Schema as McapSchema

    from services.recorder.channels import MEMORY_SCAN
    from services.recorder.reading import Record, input_kind

    t = Translator(Ros2Settings(), "front")
    scan = LaserScan(header=HEADER, angle_min=0.0, angle_increment=0.1, range_min=0.0,
                     range_max=10.0, ranges=np.array([1.5], np.float32))  # fmt: skip
    (remembered,) = t.entries("stack/scan/remembered", scan)
    (known,) = t.entries("stack/scan/known", scan)
    assert remembered.channel.topic == "/scan/remembered"
    assert known.channel.topic == "/scan/known"
    assert dict(remembered.channel.metadata)[MEMORY_SCAN] == "remembered"
    assert dict(known.channel.metadata)[MEMORY_SCAN] == "known"
    for entry in (remembered, known):
        schema = McapSchema(id=1, name="sensor_msgs/msg/LaserScan", encoding="ros2msg", data=b"")
        channel = McapChannel(id=1, topic=entry.channel.topic, message_encoding="cdr",
                              metadata=dict(entry.channel.metadata), schema_id=1)  # fmt: skip
        message = McapMessage(channel_id=1, log_time=0, data=b"", publish_time=0, sequence=0)
        assert input_kind(Record(schema, channel, message)) is None
