"""What each stack message becomes in a recording: MCAP channels, schemas and payloads. No I/O.

Messages with a ROS 2 equivalent are written as ROS 2 CDR on the ROS topic the bridge uses
(``[ros2]`` table, docs/ros2.md), with a ``ros2msg`` schema (the definition and its
dependencies), so that Foxglove, rosbags and ``ros2 bag`` read them:

    Frame (raw)        sensor_msgs/msg/Image              on ros2.image_topic
    Frame (jpeg)       sensor_msgs/msg/CompressedImage    on ros2.image_topic + "/compressed"
    LaserScan          sensor_msgs/msg/LaserScan          on ros2.scan_topic; a depth
                       camera's virtual scan on ``<scan_topic>/virtual/<camera>``, the
                       depth memory's on ``<scan_topic>/remembered`` and ``/known``
    Detections         vision_msgs/msg/Detection2DArray   on ros2.detections_topic, and
                       with depth columns vision_msgs/msg/Detection3DArray on
                       ros2.detections_3d_topic (the camera's optical frame; the boxes of
                       an unknown distance left out)
    Twist              geometry_msgs/msg/TwistStamped     on ros2.cmd_vel_topic (stamped:
                       a recording needs the command's time)
    DepthFrame         sensor_msgs/msg/Image (16UC1, 32FC1) on the camera's depth topic
                       (``/camera/depth/image_raw``), and its sensor_msgs/msg/CameraInfo on
                       ``camera_info`` beside it (depth_ros.py); the sensor's valid range in
                       the image channel's metadata (``range_min_m``, ``range_max_m``)

The image and detections topics are the first camera's (stack.camera); a further camera's
frames and detections go on its own topics, as the bridge maps them (``ros2.camera_namespace``:
``/rear/camera/rgb/image_raw``, ``/rear/detections``), the camera read from the stack key.

Everything else, and what the ROS types cannot carry (the detector's timings, the frame's
sequence, the detections' columns, the command's ``input_stamp_ns``), is JSON on the stack's
own key: Detections and Twist are written twice, once each way. The camera announcements
(CameraAnnouncement: a camera's size, rate, whether it has depth, its mounting) are JSON on
``<prefix>/camera/<camera>/announce``, one message each time a camera is announced anew.
A JSON channel has no schema record: rosbags (0.11) refuses to open a file with a
``jsonschema`` schema, so the JSON schema travels in the channel's metadata (``jsonschema``),
with the message type (``stack_message``).

An MCAP message's ``sequence`` is the stack header's ``seq``, its ``publish_time`` the header's
stamp (an announcement, which has no header: when it was heard) and its ``log_time`` when the
recorder received it.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from common.codec import Message
from common.fields import inline_fields
from common.keys import camera_in_key, memory_scan, virtual_scan_camera
from common.messages import (
    CameraAnnouncement,
    DepthFrame,
    Detections,
    Frame,
    Header,
    LaserScan,
    Twist,
)
from perception import DEPTH_CENTRE, DEPTH_SIZE
from rosmsg.convert import (
    DETECTION_2D_ARRAY,
    LASER_SCAN,
    TWIST_STAMPED,
    cdr_encode,
    detections_to_ros,
    scan_to_ros,
    twist_to_ros,
)
from rosmsg.depth import CAMERA_INFO, DETECTION_3D_ARRAY, detections_3d_to_ros
from rosmsg.distro import RosDistro
from rosmsg.images import COMPRESSED_IMAGE, IMAGE, frame_to_compressed_image, frame_to_image
from rosmsg.typestore import typestore_for
from services.recorder.depth_ros import (
    RANGE_MAX,
    RANGE_MIN,
    DepthTopics,
    depth_to_ros,
    depth_topics,
)
from services.ros2.contract import (
    CameraTopics,
    Ros2Settings,
    camera_topics,
    known_floor_topic,
    remembered_scan_topic,
    virtual_scan_topic,
)

PROFILE = "ros2"  # the MCAP profile: ros2 readers take the CDR channels as theirs
CDR, JSON = "cdr", "json"
ROS2MSG = "ros2msg"
STACK_MESSAGE = "stack_message"  # channel metadata: the stack's message type
JSON_SCHEMA = "jsonschema"  # channel metadata: the JSON schema of a JSON channel
#: Channel metadata: the depth camera whose virtual scan the channel holds. Never played back
#: (a replay would put it on the laser's key): the controller makes it again from the depth.
VIRTUAL_SCAN = "virtual_scan"
#: Channel metadata: which of the depth memory's scans (``remembered``, ``known``) the channel
#: holds. Never played back either: the depth scan stage remembers again from the depth.
MEMORY_SCAN = "memory_scan"


@dataclass(frozen=True, slots=True)
class Channel:
    """One MCAP channel: its topic, encodings and schema (``schema_name`` "" for none)."""

    topic: str
    message_encoding: str
    schema_name: str = ""
    schema_encoding: str = ""
    schema_data: bytes = b""
    metadata: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True, slots=True)
class Entry:
    """One message to write: its channel, payload, and times (``publish_ns`` None: the time
    it was received)."""

    channel: Channel
    data: bytes
    sequence: int
    publish_ns: int | None


@functools.cache
def ros2msg_schema(distro: RosDistro, ros_type: str) -> bytes:
    """The ``ros2msg`` schema of ``ros_type``: its definition, then each dependency's after a
    line of '=' and ``MSG: pkg/Name`` (what rosbag2 and Foxglove read)."""
    text, _digest = typestore_for(distro).generate_msgdef(ros_type, ros_version=2)
    return text.encode()


def _json_type(hint: Any) -> dict[str, Any]:
    """The JSON schema of one field's type hint, as :func:`to_json` writes it."""
    origin = typing.get_origin(hint)
    if origin is typing.Annotated:
        return _json_type(typing.get_args(hint)[0])
    if origin in (types.UnionType, typing.Union):
        options = [_json_type(a) for a in typing.get_args(hint) if a is not type(None)]
        return {"anyOf": [*options, {"type": "null"}]}
    if origin is np.ndarray:
        return {"type": "array"}
    if origin is tuple:
        return {"type": "array"}
    if origin in (dict, Mapping):  # Boxes' columns: name -> values
        return {"type": "object", "additionalProperties": _json_type(typing.get_args(hint)[1])}
    if dataclasses.is_dataclass(hint):
        return json_schema(hint)  # type: ignore[arg-type]
    simple = {int: "integer", float: "number", str: "string", bool: "boolean"}
    if hint in simple:
        return {"type": simple[hint]}
    raise TypeError(f"no JSON schema for {hint!r}")


def json_schema(cls: type) -> dict[str, Any]:
    """The JSON schema of a message class (or Header), from its dataclass fields; the fields of
    an inline one (Detections' boxes) are properties of the message itself, as on the wire."""
    hints = typing.get_type_hints(cls, include_extras=True)
    inline = inline_fields(cls)
    properties: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        schema = _json_type(hints[f.name])
        if f.name in inline:
            properties.update(schema["properties"])
        else:
            properties[f.name] = schema
    return {"title": cls.__name__, "type": "object", "properties": properties}


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        inline = inline_fields(type(value))
        out: dict[str, Any] = {}
        for f in dataclasses.fields(value):
            plain = _plain(getattr(value, f.name))
            if f.name in inline:
                out.update(plain)  # its fields beside the message's own, as on the wire
            else:
                out[f.name] = plain
        return out
    if isinstance(value, np.ndarray):
        if value.dtype.kind == "f" and not np.isfinite(value).all():
            return _plain(value.tolist())  # per element, for the NaN and inf
        return value.tolist()
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):  # a dict, or Boxes' columns (read-only): name -> values
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, float) and not np.isfinite(value):
        return None  # JSON has no NaN or inf
    return value


def to_json(msg: Message) -> bytes:
    """``msg`` as one JSON object, field by field (arrays as nested lists, NaN and inf as
    null: JSON has neither)."""
    return json.dumps(_plain(msg), separators=(",", ":"), allow_nan=False).encode()


def json_channel(topic: str, cls: type[Message]) -> Channel:
    """A JSON channel on ``topic`` for ``cls``, its schema in the channel's metadata."""
    schema = json.dumps(json_schema(cls), separators=(",", ":"))
    return Channel(
        topic=topic,
        message_encoding=JSON,
        metadata=((STACK_MESSAGE, cls.__name__), (JSON_SCHEMA, schema)),
    )


class Translator:
    """Turns each stack message into the entries a recording holds for it; ``first_camera``
    (stack.camera) has the ``ros2`` table's own image and detections topics."""

    def __init__(self, ros2: Ros2Settings, first_camera: str) -> None:
        self._distro = RosDistro(ros2.distro)
        self._ros2 = ros2
        self._first = first_camera
        self._channels: dict[tuple[object, ...], Channel] = {}

    def _topics(self, key: str) -> CameraTopics:
        camera = camera_in_key(key) or self._first
        return camera_topics(self._ros2, self._first, camera)

    def _depth_topics(self, key: str) -> DepthTopics:
        return depth_topics(self._ros2, self._first, camera_in_key(key) or self._first)

    def _ros_channel(
        self, topic: str, ros_type: str, stack_type: str, more: tuple[tuple[str, str], ...] = ()
    ) -> Channel:
        key = (topic, ros_type, *more)
        found = self._channels.get(key)
        if found is None:
            found = self._channels[key] = Channel(
                topic=topic,
                message_encoding=CDR,
                schema_name=ros_type,
                schema_encoding=ROS2MSG,
                schema_data=ros2msg_schema(self._distro, ros_type),
                metadata=((STACK_MESSAGE, stack_type), *more),
            )
        return found

    def _json_channel(self, key: str, cls: type[Message]) -> Channel:
        if (key, "") not in self._channels:
            self._channels[(key, "")] = json_channel(key, cls)
        return self._channels[(key, "")]

    def _ros(
        self, topic: str, ros_type: str, msg: Message, header: Header, ros: Any,
        more: tuple[tuple[str, str], ...] = (),
    ) -> Entry:  # fmt: skip
        channel = self._ros_channel(topic, ros_type, type(msg).__name__, more)
        data = cdr_encode(self._distro, ros_type, ros)
        return Entry(channel, data, header.seq, header.stamp_ns)

    def _json(self, key: str, msg: Message, header: Header) -> Entry:
        return Entry(self._json_channel(key, type(msg)), to_json(msg), header.seq, header.stamp_ns)

    def entries(self, key: str, msg: Message) -> list[Entry]:
        """What to write for ``msg``, received on the stack key ``key``."""
        if isinstance(msg, CameraAnnouncement):  # no header: no sequence, heard when received
            return [Entry(self._json_channel(key, CameraAnnouncement), to_json(msg), 0, None)]
        header: Header = msg.header  # type: ignore[attr-defined]  # every other message has one
        d, r = self._distro, self._ros2
        if isinstance(msg, Frame):
            image_topic = self._topics(key).image
            if msg.encoding == "jpeg":
                topic = f"{image_topic.rstrip('/')}/compressed"
                return [self._ros(topic, COMPRESSED_IMAGE, msg, header,
                                  frame_to_compressed_image(d, msg))]  # fmt: skip
            return [self._ros(image_topic, IMAGE, msg, header, frame_to_image(d, msg))]
        if isinstance(msg, DepthFrame):
            depth = self._depth_topics(key)
            info, image = depth_to_ros(d, msg)
            # The range as repr: a float written as text reads back the same float.
            limits = ((RANGE_MIN, repr(msg.range_min_m)), (RANGE_MAX, repr(msg.range_max_m)))
            return [  # the intrinsics first: a reader has them when the image comes
                self._ros(depth.info, CAMERA_INFO, msg, header, info),
                self._ros(depth.image, IMAGE, msg, header, image, limits),
            ]
        if isinstance(msg, LaserScan):
            ros = scan_to_ros(d, msg)
            virtual, memory = virtual_scan_camera(key), memory_scan(key)
            if virtual is not None:
                topic, more = virtual_scan_topic(r, virtual), ((VIRTUAL_SCAN, virtual),)
            elif memory is not None:
                topic = remembered_scan_topic(r) if memory == "remembered" else known_floor_topic(r)
                more = ((MEMORY_SCAN, memory),)
            else:
                return [self._ros(r.scan_topic, LASER_SCAN, msg, header, ros)]
            return [self._ros(topic, LASER_SCAN, msg, header, ros, more)]
        if isinstance(msg, Detections):
            topics = self._topics(key)
            out = [self._ros(topics.detections, DETECTION_2D_ARRAY, msg, header,
                             detections_to_ros(d, msg))]  # fmt: skip
            if all(name in msg.boxes.columns for name in (*DEPTH_CENTRE, *DEPTH_SIZE)):
                boxes_3d, _unknown = detections_3d_to_ros(d, msg)
                out.append(
                    self._ros(topics.detections_3d, DETECTION_3D_ARRAY, msg, header, boxes_3d)
                )
            return [*out, self._json(key, msg, header)]
        if isinstance(msg, Twist):
            ros = twist_to_ros(d, msg, stamped=True)
            return [
                self._ros(r.cmd_vel_topic, TWIST_STAMPED, msg, header, ros),
                self._json(key, msg, header),
            ]
        return [self._json(key, msg, header)]
