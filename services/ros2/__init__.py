"""The ros2 bridge: the stack's messages to and from ROS 2 nodes that run rmw_zenoh (issue 11).

The pure layer, exported here for other packages (the simulator plays a ROS robot with it):

    RosDistro, typestore_for      rosbags' message types per distribution, vision_msgs added
    data_key, Attachment, ...  rmw_zenoh's keys, per-sample attachment and liveliness tokens
    cdr_encode, cdr_decode     CDR as rmw_zenoh carries it; garbage raises DecodeError
    *_to_ros, *_from_ros       the translations (images in ``images.py``, the rest ``convert.py``)

and the one I/O piece other packages need: ``RosGraph``, a node in a ROS 2 graph (``graph.py``:
the session, its publishers and subscribers, their liveliness tokens). The translation modules
import no zenoh.
The wire-format facts and their sources: docs/ros2.md and services/ros2/wire.py.
"""

from typing import TYPE_CHECKING, Any

from common.ros2_settings import RosDistro
from services.ros2.convert import (
    DETECTION_2D_ARRAY,
    LASER_SCAN,
    TWIST,
    TWIST_STAMPED,
    RosMessage,
    cdr_decode,
    cdr_encode,
    detections_to_ros,
    scan_from_ros,
    scan_to_ros,
    twist_from_ros,
    twist_to_ros,
)
from services.ros2.images import (
    COMPRESSED_IMAGE,
    IMAGE,
    frame_from_compressed_image,
    frame_from_image,
    frame_to_compressed_image,
    frame_to_image,
)
from services.ros2.typestore import typestore_for
from services.ros2.wire import (
    DEFAULT_QOS,
    SENSOR_DATA_QOS,
    Attachment,
    RosQoS,
    data_key,
    endpoint_token,
    gid_for,
    node_token,
    qos_string,
    type_hash,
)

__all__ = [
    "COMPRESSED_IMAGE",
    "DEFAULT_QOS",
    "DETECTION_2D_ARRAY",
    "IMAGE",
    "LASER_SCAN",
    "SENSOR_DATA_QOS",
    "TWIST",
    "TWIST_STAMPED",
    "Attachment",
    "RosDistro",
    "RosGraph",
    "RosMessage",
    "RosPublisher",
    "RosQoS",
    "cdr_decode",
    "cdr_encode",
    "data_key",
    "detections_to_ros",
    "endpoint_token",
    "frame_from_compressed_image",
    "frame_from_image",
    "frame_to_compressed_image",
    "frame_to_image",
    "gid_for",
    "node_token",
    "qos_string",
    "scan_from_ros",
    "scan_to_ros",
    "twist_from_ros",
    "twist_to_ros",
    "type_hash",
    "typestore_for",
]

if TYPE_CHECKING:
    from services.ros2.graph import RosGraph, RosPublisher


def __getattr__(name: str) -> Any:
    # The I/O piece is imported on first use, so that the translations alone load no zenoh.
    if name in ("RosGraph", "RosPublisher"):
        from services.ros2 import graph

        return getattr(graph, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
