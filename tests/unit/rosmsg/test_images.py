"""Frames to and from sensor_msgs/Image and CompressedImage, through rosbags' CDR reader."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from common.errors import DecodeError
from common.messages import Frame, Header
from rosmsg.convert import RosMessage, build, cdr_decode, cdr_encode, ros_header
from rosmsg.distro import RosDistro
from rosmsg.images import (
    COMPRESSED_IMAGE,
    IMAGE,
    JPEG_FORMAT,
    frame_from_compressed_image,
    frame_from_image,
    frame_to_compressed_image,
    frame_to_image,
)
from rosmsg.typestore import typestore_for

STAMP_NS = 1_700_000_000_000_000_123
HEADER = Header(
    stamp_ns=STAMP_NS, frame_id="camera", seq=3, source="camera", mono_ns=9, boot_id="b"
)


def raw_frame(encoding: str, width: int = 8, height: int = 6) -> Frame:
    channels = 1 if encoding == "mono8" else 3
    data = np.random.default_rng(0).integers(0, 256, width * height * channels, dtype=np.uint8)
    return Frame(header=HEADER, encoding=encoding, width=width, height=height, data=data.tobytes())


def jpeg_frame(width: int = 64, height: int = 48) -> Frame:
    image = np.zeros((height, width, 3), np.uint8)
    cv2.rectangle(image, (5, 5), (30, 20), (0, 128, 255), -1)
    ok, buf = cv2.imencode(".jpg", image)
    assert ok
    return Frame(header=HEADER, encoding="jpeg", width=width, height=height, data=buf.tobytes())


def ros_image(distro: RosDistro, **changes: object) -> bytes:
    fields: dict[str, object] = {
        "header": ros_header(distro, STAMP_NS, "camera"),
        "height": 2,
        "width": 3,
        "encoding": "bgr8",
        "is_bigendian": 0,
        "step": 9,
        "data": np.arange(18, dtype=np.uint8),
    } | changes
    return cdr_encode(distro, IMAGE, build(distro, IMAGE, **fields))


def ros_compressed(distro: RosDistro, data: bytes, fmt: str = "jpeg") -> bytes:
    msg = build(
        distro,
        COMPRESSED_IMAGE,
        header=ros_header(distro, STAMP_NS, "camera"),
        format=fmt,
        data=np.frombuffer(data, np.uint8),
    )
    return cdr_encode(distro, COMPRESSED_IMAGE, msg)


@pytest.mark.parametrize("distro", [RosDistro.HUMBLE, RosDistro.JAZZY])
@pytest.mark.parametrize("encoding", ["bgr8", "rgb8", "mono8"])
def test_raw_frames_out_and_back(distro: RosDistro, encoding: str) -> None:
    frame = raw_frame(encoding)
    out = frame_to_image(distro, frame)
    assert out.data.base is frame.data  # the pixels are not copied on the way out
    ros: RosMessage = typestore_for(distro).deserialize_cdr(cdr_encode(distro, IMAGE, out), IMAGE)
    assert (ros.width, ros.height, ros.encoding, ros.step) == (
        8,
        6,
        encoding,
        frame.width * (1 if encoding == "mono8" else 3),
    )
    assert (ros.header.stamp.sec, ros.header.stamp.nanosec) == (1_700_000_000, 123)
    back = frame_from_image(ros, source="ros2_bridge", seq=11)
    assert (back.encoding, back.width, back.height, back.data) == (
        frame.encoding,
        frame.width,
        frame.height,
        frame.data,
    )
    # The ROS stamp is the capture stamp; a ROS header knows no monotonic clock.
    assert back.header == Header(
        stamp_ns=STAMP_NS, frame_id="camera", seq=11, source="ros2_bridge", mono_ns=0, boot_id=""
    )


def test_padded_rows_are_unpadded() -> None:
    rows = np.arange(24, dtype=np.uint8).reshape(2, 12)  # 3 bgr8 pixels (9 bytes) + 3 padding
    payload = ros_image(RosDistro.JAZZY, step=12, data=rows.ravel())
    frame = frame_from_image(cdr_decode(RosDistro.JAZZY, IMAGE, payload), source="s")
    assert frame.data == rows[:, :9].tobytes()
    mono = ros_image(RosDistro.JAZZY, encoding="mono8")  # 3 bytes a row, padded to 9
    grey = frame_from_image(cdr_decode(RosDistro.JAZZY, IMAGE, mono), source="s")
    assert grey.data == np.arange(18, dtype=np.uint8).reshape(2, 9)[:, :3].tobytes()


@pytest.mark.parametrize(
    "changes",
    [
        {"step": 8},  # shorter than a row
        {"step": 10},  # rows padded but the data is not
        {"data": np.arange(17, dtype=np.uint8)},
        {"data": np.arange(19, dtype=np.uint8)},
        {"encoding": "bgra8"},
        {"encoding": "16UC1"},
        {"encoding": "jpeg"},
        {"encoding": ""},
        {"encoding": "BGR8"},
        {"width": 0, "step": 0, "data": np.zeros(0, np.uint8)},
        {"height": 0, "data": np.zeros(0, np.uint8)},
        {"width": 20000, "height": 1, "step": 60000, "data": np.zeros(60000, np.uint8)},
    ],
)
def test_bad_images_raise_decode_error(changes: dict[str, object]) -> None:
    payload = ros_image(RosDistro.JAZZY, **changes)
    msg = cdr_decode(RosDistro.JAZZY, IMAGE, payload)
    with pytest.raises(DecodeError):
        frame_from_image(msg, source="s")


@pytest.mark.parametrize("distro", [RosDistro.HUMBLE, RosDistro.JAZZY])
def test_jpeg_frames_out_and_back(distro: RosDistro) -> None:
    frame = jpeg_frame()
    out = frame_to_compressed_image(distro, frame)
    ros: RosMessage = typestore_for(distro).deserialize_cdr(
        cdr_encode(distro, COMPRESSED_IMAGE, out), COMPRESSED_IMAGE
    )
    assert ros.format == JPEG_FORMAT
    back = frame_from_compressed_image(ros, source="ros2_bridge", seq=1)
    assert (back.encoding, back.width, back.height, back.data) == ("jpeg", 64, 48, frame.data)
    assert back.header.stamp_ns == STAMP_NS
    raw = frame_to_compressed_image(distro, frame, fmt="jpeg")
    assert raw.format == "jpeg"


@pytest.mark.parametrize(
    "fmt", ["jpeg", "JPEG", "jpg", "rgb8; jpeg compressed bgr8", "mono8; jpeg"]
)
def test_jpeg_formats_are_accepted(fmt: str) -> None:
    payload = ros_compressed(RosDistro.JAZZY, jpeg_frame(32, 16).data, fmt)
    frame = frame_from_compressed_image(
        cdr_decode(RosDistro.JAZZY, COMPRESSED_IMAGE, payload), source="s"
    )
    assert (frame.width, frame.height) == (32, 16)


@pytest.mark.parametrize(
    "fmt", ["png", "bgr8; png compressed bgr8", "16UC1; compressedDepth jpeg", ""]
)
def test_other_formats_are_refused(fmt: str) -> None:
    payload = ros_compressed(RosDistro.JAZZY, jpeg_frame().data, fmt)
    with pytest.raises(DecodeError):
        frame_from_compressed_image(
            cdr_decode(RosDistro.JAZZY, COMPRESSED_IMAGE, payload), source="s"
        )


def test_corrupt_jpegs_raise_decode_error() -> None:
    good = jpeg_frame().data
    rng = np.random.default_rng(3)
    corrupt = [b"", b"\xff\xd8", good[:20], rng.bytes(2000), b"\x89PNG\r\n\x1a\n" + good[8:]]
    # A frame header that claims an image too large (or empty) for a Frame.
    sof = good.index(b"\xff\xc0")
    corrupt.append(good[: sof + 5] + (0).to_bytes(2, "big") + good[sof + 7 :])
    corrupt.append(good[: sof + 7] + (40000).to_bytes(2, "big") + good[sof + 9 :])
    for data in corrupt:
        payload = ros_compressed(RosDistro.JAZZY, data)
        with pytest.raises(DecodeError):
            frame_from_compressed_image(
                cdr_decode(RosDistro.JAZZY, COMPRESSED_IMAGE, payload), source="s"
            )


def test_frames_go_out_as_the_matching_message_type() -> None:
    with pytest.raises(ValueError):
        frame_to_image(RosDistro.JAZZY, jpeg_frame())
    with pytest.raises(ValueError):
        frame_to_compressed_image(RosDistro.JAZZY, raw_frame("bgr8"))


def test_the_pixels_of_a_decoded_image_are_a_view_of_the_payload() -> None:
    payload = ros_image(RosDistro.JAZZY)
    msg = cdr_decode(RosDistro.JAZZY, IMAGE, payload)
    assert np.shares_memory(msg.data, np.frombuffer(payload, np.uint8))


def test_debug_image_draws_the_detections_on_their_frame() -> None:
    import cv2

    from common.boxes import Boxes
    from common.messages import Detections
    from services.ros2.debug_image import FrameCache, debug_image

    pixels = np.full((120, 160, 3), 255, np.uint8)
    header = Header(stamp_ns=5, frame_id="camera", seq=1, source="cam")
    frame = Frame(header=header, encoding="bgr8", width=160, height=120, data=pixels.tobytes())
    boxes = Boxes(
        xyxy=np.array([[20, 20, 100, 100]], np.float32),
        scores=np.array([0.9], np.float32),
        class_ids=np.zeros(1, np.int32),
        track_ids=np.array([7], np.int32),
    )
    dets = Detections(
        header=header, image_width=160, image_height=120, boxes=boxes, class_names=("person",)
    )
    cache = FrameCache(size=3)
    for stamp in (1, 2, 5, 9):
        cache.add(frame if stamp == 5 else dataclasses.replace(frame, header=dataclasses.replace(
            header, stamp_ns=stamp)))  # fmt: skip
    assert cache.take(5) is frame and cache.take(5) is None  # taken, and older ones forgotten
    drawn = debug_image(frame, dets, jpeg_quality=90)
    assert drawn.encoding == "jpeg" and drawn.header == header
    image = cv2.imdecode(np.frombuffer(drawn.data, np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (120, 160, 3)
    assert image[20, 60].min() < 200  # the box's top edge is drawn where the frame was white
    assert image[110, 150].min() > 240  # far from the box, untouched
