"""Writes the CDR fixtures beside it with ROS 2's own serializer (rclpy, Kilted wheels), so that
the bridge's depth decoding is tested on bytes ROS 2 wrote, without a ROS install in CI.

Run it in a venv of its own (Python 3.11; the wheels are large: keep them out of the stack's):

    python3.11 -m venv /tmp/rclpy && /tmp/rclpy/bin/pip install ros-rclpy ros-sensor-msgs \
        ros-std-msgs ros-builtin-interfaces ros-rmw-fastrtps-cpp ros-wheels-bootstrapper numpy
    /tmp/rclpy/bin/python tests/unit/ros2/data/make_rclpy_cdr.py

The pictures: a 16 x 12 ramp, 400 mm + 10 mm per pixel (16UC1), the same in metres (32FC1);
the CameraInfo: fx 300, fy 310, cx 7.5, cy 5.5. tests/unit/ros2/test_depth_handlers.py states
the same.
"""

from pathlib import Path

import numpy as np
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo, Image

HERE = Path(__file__).parent
W, H = 16, 12
FRAME = "camera_color_optical_frame"


def main() -> None:
    mm = np.arange(W * H, dtype=np.uint16).reshape(H, W) * 10 + 400
    for encoding, pixels in (("16UC1", mm), ("32FC1", (mm / 1000).astype(np.float32))):
        image = Image()
        image.header.stamp.sec, image.header.stamp.nanosec = 1_700_000_000, 123
        image.header.frame_id = FRAME
        image.height, image.width, image.encoding, image.is_bigendian = H, W, encoding, 0
        image.step = W * pixels.itemsize
        image.data = pixels.tobytes()
        (HERE / f"rclpy_{encoding}.cdr").write_bytes(serialize_message(image))
    info = CameraInfo()
    info.header.frame_id = FRAME
    info.height, info.width = H, W
    info.distortion_model = "plumb_bob"
    info.k = [300.0, 0.0, 7.5, 0.0, 310.0, 5.5, 0.0, 0.0, 1.0]
    (HERE / "rclpy_camera_info.cdr").write_bytes(serialize_message(info))


if __name__ == "__main__":
    main()
