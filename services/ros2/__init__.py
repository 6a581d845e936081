"""The ros2 bridge: the stack's messages to and from ROS 2 nodes that run rmw_zenoh (issue 11).

The pure layer, exported here for other packages (the simulator plays a ROS robot with it):

    RosDistro, typestore_for      rosbags' message types per distribution, vision_msgs added
    data_key, Attachment, ...  rmw_zenoh's keys, per-sample attachment and liveliness tokens
    cdr_encode, cdr_decode     CDR as rmw_zenoh carries it; garbage raises DecodeError
    *_to_ros, *_from_ros       the translations (images in ``images.py``, depth and 3D
                               detections in ``depth.py``, the rest ``convert.py``)

and the one I/O piece other packages need: ``RosGraph``, a node in a ROS 2 graph (``graph.py``:
the session, its publishers and subscribers, their liveliness tokens). The translation modules
import no zenoh.
The wire-format facts and their sources: docs/ros2.md and services/ros2/wire.py.
"""

from typing import TYPE_CHECKING

from common.lazy import exports

if TYPE_CHECKING:
    from services.ros2.contract import RosDistro
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
    from services.ros2.depth import (
        CAMERA_INFO,
        DETECTION_3D_ARRAY,
        camera_info_of,
        depth_from_image,
        depth_to_image,
        detections_3d_to_ros,
        intrinsics_from_camera_info,
    )
    from services.ros2.graph import RosGraph, RosPublisher
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
    "CAMERA_INFO",
    "COMPRESSED_IMAGE",
    "DEFAULT_QOS",
    "DETECTION_2D_ARRAY",
    "DETECTION_3D_ARRAY",
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
    "camera_info_of",
    "cdr_decode",
    "cdr_encode",
    "data_key",
    "depth_from_image",
    "depth_to_image",
    "detections_3d_to_ros",
    "detections_to_ros",
    "endpoint_token",
    "frame_from_compressed_image",
    "frame_from_image",
    "frame_to_compressed_image",
    "frame_to_image",
    "gid_for",
    "intrinsics_from_camera_info",
    "node_token",
    "qos_string",
    "scan_from_ros",
    "scan_to_ros",
    "twist_from_ros",
    "twist_to_ros",
    "type_hash",
    "typestore_for",
]

# Imported on first use: the bridge's contract (services/ros2/contract.py) loads none of it, and
# the translations alone load no zenoh (the I/O piece, graph.py, comes only with RosGraph).
__getattr__ = exports(
    __name__,
    {
        "RosDistro": "services.ros2.contract",
        "DETECTION_2D_ARRAY": "services.ros2.convert",
        "LASER_SCAN": "services.ros2.convert",
        "TWIST": "services.ros2.convert",
        "TWIST_STAMPED": "services.ros2.convert",
        "RosMessage": "services.ros2.convert",
        "cdr_decode": "services.ros2.convert",
        "cdr_encode": "services.ros2.convert",
        "detections_to_ros": "services.ros2.convert",
        "scan_from_ros": "services.ros2.convert",
        "scan_to_ros": "services.ros2.convert",
        "twist_from_ros": "services.ros2.convert",
        "twist_to_ros": "services.ros2.convert",
        "CAMERA_INFO": "services.ros2.depth",
        "DETECTION_3D_ARRAY": "services.ros2.depth",
        "camera_info_of": "services.ros2.depth",
        "depth_from_image": "services.ros2.depth",
        "depth_to_image": "services.ros2.depth",
        "detections_3d_to_ros": "services.ros2.depth",
        "intrinsics_from_camera_info": "services.ros2.depth",
        "COMPRESSED_IMAGE": "services.ros2.images",
        "IMAGE": "services.ros2.images",
        "frame_from_compressed_image": "services.ros2.images",
        "frame_from_image": "services.ros2.images",
        "frame_to_compressed_image": "services.ros2.images",
        "frame_to_image": "services.ros2.images",
        "typestore_for": "services.ros2.typestore",
        "DEFAULT_QOS": "services.ros2.wire",
        "SENSOR_DATA_QOS": "services.ros2.wire",
        "Attachment": "services.ros2.wire",
        "RosQoS": "services.ros2.wire",
        "data_key": "services.ros2.wire",
        "endpoint_token": "services.ros2.wire",
        "gid_for": "services.ros2.wire",
        "node_token": "services.ros2.wire",
        "qos_string": "services.ros2.wire",
        "type_hash": "services.ros2.wire",
        "RosGraph": "services.ros2.graph",
        "RosPublisher": "services.ros2.graph",
    },
)
