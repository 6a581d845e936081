"""Reading what a Foxglove server sends, as the Foxglove app does, with libraries we did not
write: the ``foxglove.sdk.v1`` WebSocket protocol (JSON text frames; binary frames with opcode
1 for messages) and protobuf messages decoded from the schema the channel advertises (a
base64 FileDescriptorSet) by google.protobuf."""

from __future__ import annotations

import base64
import json
import struct
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, json_format, message_factory

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 1  # the opcode of a binary message frame


def protobuf_decoder(schema_name: str, file_descriptor_set: bytes) -> Any:
    """The message class named ``schema_name`` in ``file_descriptor_set``."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(file_descriptor_set)
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def decode_protobuf(schema_name: str, file_descriptor_set: bytes, data: bytes) -> dict[str, Any]:
    """One message as a dict (protobuf's JSON mapping: camelCase names, bytes as base64)."""
    cls = protobuf_decoder(schema_name, file_descriptor_set)
    return json_format.MessageToDict(cls.FromString(data))


def decode_channel_message(channel: dict[str, Any], data: bytes) -> dict[str, Any]:
    """A message of an advertised ``channel`` (its advertise entry) as a dict."""
    if channel["encoding"] == "json":
        return dict(json.loads(data))
    assert channel["encoding"] == "protobuf", channel
    schema = base64.b64decode(channel["schema"])
    return decode_protobuf(channel["schemaName"], schema, data)


def split_message_frame(frame: bytes) -> tuple[int, int, bytes]:
    """A binary message frame: (subscription id, log time in ns, payload)."""
    opcode, sub_id, log_time = struct.unpack_from("<BIQ", frame)
    assert opcode == MESSAGE_DATA, f"opcode {opcode}"
    return sub_id, log_time, frame[13:]
