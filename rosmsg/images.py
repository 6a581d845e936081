"""Translations between camera Frames and ROS ``sensor_msgs/Image`` / ``CompressedImage``.

No I/O. Bad input raises ``DecodeError`` and nothing else; see rosmsg/convert.py for the
header conventions and the CDR helpers.
"""

from __future__ import annotations

import numpy as np

from common.errors import DecodeError
from common.frames import jpeg_size
from common.messages import FRAME_ENCODINGS, Frame, Header
from rosmsg.convert import RosMessage, build, header_from_ros, ros_header
from rosmsg.distro import RosDistro

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"

#: What a jpeg Frame is sent as: image_transport's "compressed" convention (cv2 JPEGs are BGR).
JPEG_FORMAT = "bgr8; jpeg compressed bgr8"


def frame_from_image(msg: RosMessage, *, source: str, seq: int = 0) -> Frame:
    """A ``sensor_msgs/Image`` (bgr8, rgb8 or mono8) as a raw Frame.

    ``step`` may pad each row (ROS allows it); the padding is dropped. Costs one copy of the
    pixels, which a Frame must own as bytes.
    """
    encoding = str(msg.encoding)
    channels = FRAME_ENCODINGS.get(encoding, 0)
    if not channels:  # 0 also for "jpeg", which is no raw ROS encoding
        raise DecodeError(f"Image: unsupported encoding {encoding!r} (bgr8, rgb8, mono8)")
    width, height, step = int(msg.width), int(msg.height), int(msg.step)
    data = msg.data
    row = width * channels
    if step < row or len(data) != step * height:
        raise DecodeError(
            f"Image: {encoding} {width}x{height} with step {step} needs step >= {row} and "
            f"step*height bytes, got {len(data)}"
        )
    if step != row and height:
        data = data.reshape(height, step)[:, :row]  # tobytes() below copies it compactly
    header = header_from_ros(msg.header, source=source, seq=seq)
    try:
        return Frame(
            header=header, encoding=encoding, width=width, height=height, data=data.tobytes()
        )
    except ValueError as exc:
        raise DecodeError(f"Image: {exc}") from exc


def frame_from_compressed_image(msg: RosMessage, *, source: str, seq: int = 0) -> Frame:
    """A JPEG ``sensor_msgs/CompressedImage`` as a jpeg Frame, sized from its own header.

    Only the JPEG headers are read here (a corrupt body is the decoder's to find).
    """
    fmt = str(msg.format).lower()
    if ("jpeg" not in fmt and "jpg" not in fmt) or "compresseddepth" in fmt:
        raise DecodeError(f"CompressedImage: unsupported format {msg.format!r} (jpeg only)")
    data = msg.data.tobytes()
    size = jpeg_size(data)
    if size is None:
        raise DecodeError(f"CompressedImage: corrupt JPEG ({len(data)} bytes, no frame header)")
    header = header_from_ros(msg.header, source=source, seq=seq)
    try:
        return Frame(header=header, encoding="jpeg", width=size[0], height=size[1], data=data)
    except ValueError as exc:
        raise DecodeError(f"CompressedImage: {exc}") from exc


def frame_to_image(distro: RosDistro, frame: Frame) -> RosMessage:
    """A raw Frame as a ``sensor_msgs/Image`` (rows unpadded); the pixels are not copied."""
    channels = FRAME_ENCODINGS[frame.encoding]
    if not channels:
        raise ValueError("a jpeg Frame is a CompressedImage: use frame_to_compressed_image")
    return raw_image(distro, frame.header, frame.encoding, frame.width, frame.height,
                     channels, frame.data)  # fmt: skip


def raw_image(
    distro: RosDistro,
    header: Header,
    encoding: str,
    width: int,
    height: int,
    pixel_bytes: int,
    data: bytes,
) -> RosMessage:
    """A ``sensor_msgs/Image`` of raw little-endian rows, unpadded, with ``header``'s stamp and
    frame id; ``data`` is not copied."""
    return build(
        distro,
        IMAGE,
        header=ros_header(distro, header.stamp_ns, header.frame_id),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=width * pixel_bytes,
        data=np.frombuffer(data, dtype=np.uint8),
    )


def frame_to_compressed_image(
    distro: RosDistro, frame: Frame, *, fmt: str = JPEG_FORMAT
) -> RosMessage:
    """A jpeg Frame as a ``sensor_msgs/CompressedImage``."""
    if frame.encoding != "jpeg":
        raise ValueError(f"a {frame.encoding} Frame is an Image: use frame_to_image")
    return build(
        distro,
        COMPRESSED_IMAGE,
        header=ros_header(distro, frame.header.stamp_ns, frame.header.frame_id),
        format=fmt,
        data=np.frombuffer(frame.data, dtype=np.uint8),
    )
