"""Scans, twists and detections to and from ROS, checked through rosbags' own CDR reader."""

from __future__ import annotations

import contextlib
import math

import numpy as np
import pytest

from common.boxes import Boxes
from common.errors import DecodeError
from common.messages import Detections, Frame, Header, LaserScan, Twist
from rosmsg.convert import (
    DETECTION_2D_ARRAY,
    LASER_SCAN,
    TWIST,
    TWIST_STAMPED,
    RosMessage,
    build,
    cdr_decode,
    cdr_encode,
    detections_to_ros,
    header_from_ros,
    ros_header,
    scan_from_ros,
    scan_to_ros,
    twist_from_ros,
    twist_to_ros,
)
from rosmsg.distro import RosDistro
from rosmsg.images import frame_to_image
from rosmsg.typestore import typestore_for

STAMP_NS = 1_700_000_000_123_456_789
DISTROS = [RosDistro.HUMBLE, RosDistro.JAZZY, RosDistro.KILTED, RosDistro.ROLLING]


def header(frame_id: str = "camera") -> Header:
    return Header(stamp_ns=STAMP_NS, frame_id=frame_id, seq=9, source="camera", mono_ns=5)


def roundtrip(distro: RosDistro, ros_type: str, msg: RosMessage) -> RosMessage:
    """``msg`` through CDR, read back by rosbags itself (not by our cdr_decode)."""
    payload = cdr_encode(distro, ros_type, msg)
    assert payload[:4] == b"\x00\x01\x00\x00"  # CDR little-endian, as rmw_zenoh sends
    return typestore_for(distro).deserialize_cdr(payload, ros_type)


def test_a_twist_is_52_bytes_of_cdr() -> None:
    twist = Twist(header=header("base_link"), linear=(0.5, 0, 0), angular=(0, 0, -0.25))
    assert len(cdr_encode(RosDistro.JAZZY, TWIST, twist_to_ros(RosDistro.JAZZY, twist))) == 52


@pytest.mark.parametrize("distro", DISTROS)
def test_twist_out_and_back(distro: RosDistro) -> None:
    twist = Twist(header=header("base_link"), linear=(0.5, 0.0, 0.0), angular=(0.0, 0.0, -0.25))
    ros = roundtrip(distro, TWIST, twist_to_ros(distro, twist))
    assert (ros.linear.x, ros.angular.z) == (0.5, -0.25)
    back = twist_from_ros(ros, source="ros2", received_ns=123, seq=4)
    assert (back.linear, back.angular) == (twist.linear, twist.angular)
    # A bare Twist carries no stamp: it is stamped on receipt, in base_link.
    assert (back.header.stamp_ns, back.header.frame_id, back.header.seq) == (123, "base_link", 4)
    assert back.header.source == "ros2"


@pytest.mark.parametrize("distro", DISTROS)
def test_twist_stamped_out_and_back(distro: RosDistro) -> None:
    twist = Twist(header=header("ignored"), linear=(1.0, 0.0, 0.0), angular=(0.0, 0.0, 0.5))
    ros = roundtrip(distro, TWIST_STAMPED, twist_to_ros(distro, twist, stamped=True))
    assert ros.header.frame_id == "base_link"
    assert (ros.header.stamp.sec, ros.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    back = twist_from_ros(ros, source="ros2", received_ns=1)
    assert back.header.stamp_ns == STAMP_NS
    assert (back.header.mono_ns, back.header.boot_id) == (0, "")
    assert (back.linear, back.angular) == (twist.linear, twist.angular)
    odom = twist_to_ros(distro, twist, stamped=True, frame_id="odom")
    assert odom.header.frame_id == "odom"


def test_non_finite_ros_twists_are_refused() -> None:
    vector3 = typestore_for(RosDistro.JAZZY).types["geometry_msgs/msg/Vector3"]
    for bad in (math.nan, math.inf, -math.inf):
        ros = build(
            RosDistro.JAZZY, TWIST, linear=vector3(bad, 0.0, 0.0), angular=vector3(0.0, 0.0, 0.0)
        )
        payload = cdr_encode(RosDistro.JAZZY, TWIST, ros)
        with pytest.raises(DecodeError):
            twist_from_ros(cdr_decode(RosDistro.JAZZY, TWIST, payload), source="s", received_ns=0)


def make_scan(n: int = 360) -> LaserScan:
    ranges = np.linspace(0.2, 9.0, n, dtype=np.float32)
    ranges[3], ranges[5] = np.inf, np.nan
    return LaserScan(
        header=header("laser"),
        angle_min=-math.pi,
        angle_increment=2 * math.pi / n,
        range_min=0.1,
        range_max=10.0,
        ranges=ranges,
    )


@pytest.mark.parametrize("distro", DISTROS)
def test_scan_out_and_back(distro: RosDistro) -> None:
    scan = make_scan()
    ros = roundtrip(distro, LASER_SCAN, scan_to_ros(distro, scan))
    assert ros.angle_max == pytest.approx(scan.angle_min + 359 * scan.angle_increment)
    assert len(ros.intensities) == 0
    back = scan_from_ros(ros, source="ros2", seq=2)
    np.testing.assert_array_equal(back.ranges, scan.ranges)
    assert back.ranges.dtype == np.float32 and back.ranges.flags.writeable
    # ROS carries angles and ranges as float32.
    assert back.angle_min == pytest.approx(scan.angle_min, rel=1e-6)
    assert back.angle_increment == pytest.approx(scan.angle_increment, rel=1e-6)
    assert (back.range_min, back.range_max) == pytest.approx(
        (scan.range_min, scan.range_max), rel=1e-6
    )
    assert (back.header.stamp_ns, back.header.frame_id, back.header.seq) == (STAMP_NS, "laser", 2)


def ros_scan(distro: RosDistro, **changes: object) -> bytes:
    fields: dict[str, object] = {
        "header": ros_header(distro, STAMP_NS, "laser"),
        "angle_min": -1.0,
        "angle_max": 1.0,
        "angle_increment": 0.5,
        "time_increment": 0.0,
        "scan_time": 0.1,
        "range_min": 0.1,
        "range_max": 10.0,
        "ranges": np.ones(5, dtype=np.float32),
        "intensities": np.zeros(0, dtype=np.float32),
    } | changes
    return cdr_encode(distro, LASER_SCAN, build(distro, LASER_SCAN, **fields))


def test_a_big_endian_scan_decodes_to_native_floats() -> None:
    store = typestore_for(RosDistro.JAZZY)
    msg = store.deserialize_cdr(ros_scan(RosDistro.JAZZY), LASER_SCAN)
    big = bytes(store.serialize_cdr(msg, LASER_SCAN, little_endian=False))
    assert big[:2] == b"\x00\x00"
    scan = scan_from_ros(cdr_decode(RosDistro.JAZZY, LASER_SCAN, big), source="s")
    np.testing.assert_array_equal(scan.ranges, np.ones(5, dtype=np.float32))


@pytest.mark.parametrize(
    "changes",
    [
        {"ranges": np.zeros(0, dtype=np.float32)},
        {"range_min": 5.0, "range_max": 1.0},
        {"range_min": -1.0},
        {"range_max": math.nan},
        {"angle_min": math.inf},
        {"angle_increment": math.nan},
    ],
)
def test_scans_the_stack_would_refuse_raise_decode_error(changes: dict[str, object]) -> None:
    payload = ros_scan(RosDistro.JAZZY, **changes)
    with pytest.raises(DecodeError):
        scan_from_ros(cdr_decode(RosDistro.JAZZY, LASER_SCAN, payload), source="s")


def make_detections(n: int = 10, tracks: bool = True) -> Detections:
    rng = np.random.default_rng(1)
    xy = rng.uniform(0, 500, (n, 2)).astype(np.float32)
    wh = rng.uniform(1, 100, (n, 2)).astype(np.float32)
    track_ids = np.arange(n, dtype=np.int32) if tracks else None
    if track_ids is not None and n:
        track_ids[0] = -1
    return Detections(
        header=header(),
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.hstack([xy, xy + wh]),
            scores=rng.uniform(0.3, 1.0, n).astype(np.float32),
            class_ids=np.zeros(n, dtype=np.int32),
            track_ids=track_ids,
        ),
        class_names=tuple("person" if i % 2 else "dog" for i in range(n)),
    )


@pytest.mark.parametrize("distro", DISTROS)
def test_detections_out(distro: RosDistro) -> None:
    dets = make_detections()
    ros = roundtrip(distro, DETECTION_2D_ARRAY, detections_to_ros(distro, dets))
    assert ros.header.frame_id == "camera"
    assert (ros.header.stamp.sec, ros.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert len(ros.detections) == 10
    for i, det in enumerate(ros.detections):
        assert det.header == ros.header
        assert len(det.results) == 1
        hypothesis = det.results[0].hypothesis
        assert hypothesis.class_id == dets.class_names[i]
        assert hypothesis.score == pytest.approx(float(dets.boxes.scores[i]))
        assert det.results[0].pose.pose.orientation.w == 1.0
        x1, y1, x2, y2 = dets.boxes.xyxy[i].astype(float)
        assert det.bbox.center.position.x == pytest.approx((x1 + x2) / 2)
        assert det.bbox.center.position.y == pytest.approx((y1 + y2) / 2)
        assert (det.bbox.size_x, det.bbox.size_y) == pytest.approx((x2 - x1, y2 - y1))
        assert det.bbox.center.theta == 0.0
        assert det.id == ("" if i == 0 else str(i))  # track -1: no id


def test_detections_without_tracks_and_empty_ones() -> None:
    ros = detections_to_ros(RosDistro.JAZZY, make_detections(3, tracks=False))
    assert [d.id for d in ros.detections] == ["", "", ""]
    empty = roundtrip(
        RosDistro.JAZZY, DETECTION_2D_ARRAY, detections_to_ros(RosDistro.JAZZY, make_detections(0))
    )
    assert empty.detections == []


def test_header_from_ros_refuses_impossible_stamps() -> None:
    store = typestore_for(RosDistro.JAZZY)
    time, ros_hdr = store.types["builtin_interfaces/msg/Time"], store.types["std_msgs/msg/Header"]
    for sec, nanosec in ((-1, 0), (0, 1_000_000_000)):
        with pytest.raises(DecodeError):
            header_from_ros(ros_hdr(stamp=time(sec=sec, nanosec=nanosec), frame_id="f"), source="s")
    ok = header_from_ros(ros_hdr(stamp=time(sec=2, nanosec=3), frame_id="f"), source="s", seq=1)
    assert ok == Header(stamp_ns=2_000_000_003, frame_id="f", seq=1, source="s")


def test_ros_header_refuses_stamps_a_ros_time_cannot_hold() -> None:
    with pytest.raises(ValueError):
        ros_header(RosDistro.JAZZY, 2**31 * 1_000_000_000, "f")


ALL_TYPES = [
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CompressedImage",
    LASER_SCAN,
    TWIST,
    TWIST_STAMPED,
    DETECTION_2D_ARRAY,
]


@pytest.mark.parametrize("ros_type", ALL_TYPES)
def test_random_bytes_raise_decode_error_only(ros_type: str) -> None:
    rng = np.random.default_rng(7)
    for n in [*range(0, 16), *rng.integers(16, 4096, 200).tolist()]:
        payload = rng.bytes(n)
        for prefix in (b"", b"\x00\x01\x00\x00", b"\x00\x00\x00\x00"):
            with contextlib.suppress(DecodeError):  # anything else fails the test
                cdr_decode(RosDistro.JAZZY, ros_type, prefix + payload)


def _valid_payloads(distro: RosDistro) -> dict[str, bytes]:
    frame = Frame(header=header(), encoding="bgr8", width=4, height=2, data=bytes(range(24)))
    twist = Twist(header=header("base_link"), linear=(0.5, 0, 0))
    return {
        "sensor_msgs/msg/Image": cdr_encode(
            distro, "sensor_msgs/msg/Image", frame_to_image(distro, frame)
        ),
        LASER_SCAN: cdr_encode(distro, LASER_SCAN, scan_to_ros(distro, make_scan(8))),
        TWIST: cdr_encode(distro, TWIST, twist_to_ros(distro, twist)),
        TWIST_STAMPED: cdr_encode(distro, TWIST_STAMPED, twist_to_ros(distro, twist, stamped=True)),
        DETECTION_2D_ARRAY: cdr_encode(
            distro, DETECTION_2D_ARRAY, detections_to_ros(distro, make_detections(3))
        ),
    }


@pytest.mark.parametrize("distro", [RosDistro.HUMBLE, RosDistro.JAZZY])
def test_truncated_and_padded_cdr_raises_decode_error(distro: RosDistro) -> None:
    for ros_type, payload in _valid_payloads(distro).items():
        assert cdr_decode(distro, ros_type, payload) is not None
        for cut in range(len(payload) - 4):  # keep at most 3 bytes of CDR alignment slack
            with pytest.raises(DecodeError):
                cdr_decode(distro, ros_type, payload[:cut])
        with pytest.raises(DecodeError):
            cdr_decode(distro, ros_type, payload + bytes(8))
        with pytest.raises(DecodeError):
            cdr_decode(distro, ros_type, b"\x00\x02" + payload[2:])  # not plain CDR


def test_cdr_decode_accepts_bytes_bytearray_and_memoryview() -> None:
    payload = _valid_payloads(RosDistro.JAZZY)[TWIST]
    for form in (payload, bytearray(payload), memoryview(payload)):
        assert cdr_decode(RosDistro.JAZZY, TWIST, form).linear.x == 0.5


def test_cdr_decode_refuses_an_unknown_type_as_a_caller_error() -> None:
    with pytest.raises(ValueError):
        cdr_decode(RosDistro.JAZZY, "nosuch_msgs/msg/Thing", b"\x00\x01\x00\x00")
