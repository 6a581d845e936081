"""Every message round-trips, and every kind of garbage raises DecodeError and nothing else."""

from __future__ import annotations

import contextlib
import dataclasses

import msgpack
import numpy as np
import pytest

from common.boxes import Boxes
from common.codec import Message
from common.errors import DecodeError
from common.messages import (
    MAX_SCAN_RAYS,
    ControllerStatus,
    Detections,
    EStop,
    Frame,
    GroundTruth,
    Header,
    LaserScan,
    MetricsSnapshot,
    ServiceCounters,
    Twist,
)

HEADER = Header(stamp_ns=1_700_000_000_123_456_789, frame_id="camera", seq=42, source="test")


def _detections(n: int = 3, tracks: bool = True) -> Detections:
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 300, (n, 2)).astype(np.float32)
    return Detections(
        header=HEADER,
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.hstack([xy, xy + 20]),
            scores=rng.uniform(0, 1, n).astype(np.float32),
            class_ids=np.arange(n, dtype=np.int32),
            track_ids=np.arange(n, dtype=np.int32) if tracks else None,
        ),
        class_names=tuple(f"c{i}" for i in range(n)),
        timing_ms={"inference": 80.5},
        model="m.onnx",
        backend="onnx/cpu/fp32",
        received_ns=HEADER.stamp_ns + 5,
        published_ns=HEADER.stamp_ns + 90,
    )


MESSAGES = [
    Frame(header=HEADER, encoding="bgr8", width=4, height=2, data=bytes(range(24))),
    Frame(header=HEADER, encoding="mono8", width=3, height=1, data=b"\x00\x01\x02"),
    Frame(header=HEADER, encoding="jpeg", width=640, height=480, data=b"\xff\xd8fakejpeg"),
    _detections(),
    _detections(0, tracks=False),
    Twist(header=HEADER, linear=(0.3, 0.0, 0.0), angular=(0.0, 0.0, -0.5), input_stamp_ns=7),
    LaserScan(
        header=HEADER,
        angle_min=-1.0,
        angle_increment=0.01,
        range_min=0.1,
        range_max=10.0,
        ranges=np.array([1.0, np.inf, np.nan], np.float32),
    ),
    ControllerStatus(
        header=HEADER,
        mode="follow",
        target="person",
        state="following",
        reason="offset +0.01",
        track_id=3,
        camera="rear",
        target_classes=("person", "dog"),
    ),
    ServiceCounters(header=HEADER, service="detector", counters={"dropped": 3, "bad_input": 1}),
    EStop(header=HEADER, engaged=True, reason="operator"),
    GroundTruth(
        header=HEADER,
        sim_time_s=1.5,
        robot=(1.0, -2.0, 0.5),
        robot_velocity=(0.2, 0.1),
        targets_xy=np.array([[3.0, 1.0], [4.0, -1.0]]),
        target_names=("person", "cat"),
        target_ids=("alice", "tom"),
        obstacles=np.array([[2.0, 0.5, 0.3]]),
    ),
    MetricsSnapshot(
        header=HEADER,
        window_s=10.0,
        fps=9.5,
        frames=100,
        detections=120,
        detections_per_frame=1.2,
        dropped_frames=4,
        latency_ms={"end_to_end": {"p50": 90.0, "p95": 120.0}},
        counters={"detector.bad_input": 2},
        class_counts={"person": 100},
    ),
]


def _equal(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and np.array_equal(a, b, True)
    if a is None or b is None:
        return a is b
    if hasattr(a, "__slots__") and hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(
            _equal(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__
        )
    return a == b


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: type(m).__name__)
def test_round_trip(msg: object) -> None:
    decoded = type(msg).decode(msg.encode())  # type: ignore[attr-defined]
    assert _equal(decoded, msg)


def test_detections_carry_centre_and_size() -> None:
    d = _detections()
    body = msgpack.unpackb(d.encode())["d"]
    cs = np.frombuffer(body["center_size"], "<f4").reshape(-1, 4)
    np.testing.assert_allclose(cs[:, :2], (d.boxes.xyxy[:, :2] + d.boxes.xyxy[:, 2:]) / 2)
    np.testing.assert_allclose(cs[:, 2:], d.boxes.xyxy[:, 2:] - d.boxes.xyxy[:, :2])


@pytest.mark.parametrize("cls", [type(m) for m in MESSAGES[::2]] + [Twist, LaserScan])
def test_random_bytes_raise_decode_error(cls: type) -> None:
    rng = np.random.default_rng(1)
    for size in (0, 1, 7, 64, 4096):
        for _ in range(20):
            with pytest.raises(DecodeError):
                cls.decode(rng.bytes(size))


def _rewrite(payload: bytes, **changes: object) -> bytes:
    env = msgpack.unpackb(payload)
    body = env["d"]
    for key, value in changes.items():
        if key in ("v", "t"):
            env[key] = value
        else:
            body[key] = value
    return msgpack.packb(env)


def test_wrong_schema_version() -> None:
    payload = _rewrite(MESSAGES[0].encode(), v=Frame.VERSION + 1)
    with pytest.raises(DecodeError, match="schema version"):
        Frame.decode(payload)


def test_wrong_message_type() -> None:
    with pytest.raises(DecodeError, match="expected a Frame"):
        Frame.decode(MESSAGES[5].encode())


def test_truncated_frame() -> None:
    good = MESSAGES[0].encode()
    with pytest.raises(DecodeError):
        Frame.decode(good[: len(good) // 2])
    short_pixels = _rewrite(good, data=bytes(10))
    with pytest.raises(DecodeError, match="needs 24 bytes"):
        Frame.decode(short_pixels)


@pytest.mark.parametrize("w,h", [(0, 2), (-4, 2), (100_000, 100_000), (2**40, 1)])
def test_absurd_dimensions(w: int, h: int) -> None:
    with pytest.raises(DecodeError):
        Frame.decode(_rewrite(MESSAGES[0].encode(), width=w, height=h))


def test_wrong_field_types() -> None:
    good = MESSAGES[3].encode()
    for change in (
        {"n": "three"},
        {"n": 5},
        {"xyxy": b"\x00" * 7},
        {"class_names": [1, 2, 3]},
        {"header": "nope"},
        {"timing_ms": {"x": "slow"}},
    ):
        with pytest.raises(DecodeError):
            Detections.decode(_rewrite(good, **change))
    for bad in ([0.1, 0.2], [float("nan"), 0, 0], ["a", 0, 0]):
        with pytest.raises(DecodeError):
            Twist.decode(_rewrite(MESSAGES[5].encode(), linear=bad))


def test_constructor_validates_shapes() -> None:
    with pytest.raises(ValueError, match="xyxy"):
        Detections(
            header=HEADER,
            image_width=10,
            image_height=10,
            boxes=Boxes(
                xyxy=np.zeros((3, 4), np.float32),
                scores=np.zeros(2, np.float32),
                class_ids=np.zeros(2, np.int32),
            ),
            class_names=("a", "b"),
        )


def test_detections_and_twists_refuse_non_finite_or_inverted_values() -> None:
    good = _detections(2)
    for bad in (
        np.array([[0, 0, np.nan, 1], [0, 0, 1, 1]], np.float32),
        np.array([[0, 0, 1, 1], [5, 5, 1, 1]], np.float32),
    ):
        with pytest.raises(ValueError):
            Detections(
                header=HEADER,
                image_width=640,
                image_height=480,
                boxes=Boxes(xyxy=bad, scores=good.boxes.scores, class_ids=good.boxes.class_ids),
                class_names=good.class_names,
            )
    body = msgpack.unpackb(good.encode())
    body["d"]["timing_ms"] = {"inference": float("nan")}
    with pytest.raises(DecodeError):
        Detections.decode(msgpack.packb(body))
    with pytest.raises(ValueError):
        Twist(header=HEADER, linear=(float("nan"), 0.0, 0.0))


# The wire names of every message, pinned: docs/messages.md and readers in other languages use
# them. "n" is the count that sizes the arrays; center_size and MetricsSnapshot's top-level
# stamp_ns are derived extras that decoders ignore.
HEADER_KEYS = {"stamp_ns", "frame_id", "seq", "source", "mono_ns", "boot_id"}
WIRE_KEYS = {
    "Frame": {"header", "encoding", "width", "height", "data"},
    "Detections": {
        "header", "image_width", "image_height", "n", "class_ids", "class_names", "scores",
        "xyxy", "center_size", "track_ids", "columns", "timing_ms", "model", "backend",
        "received_ns", "published_ns", "worker",
    },
    "Twist": {"header", "linear", "angular", "input_stamp_ns"},
    "LaserScan": {
        "header", "angle_min", "angle_increment", "range_min", "range_max", "n", "ranges"
    },
    "ControllerStatus": {"header", "mode", "target", "state", "reason", "track_id",
                         "estop_saved", "camera", "stale_cameras", "no_laser", "target_classes"},
    "ServiceCounters": {"header", "service", "counters"},
    "EStop": {"header", "engaged", "reason"},
    "GroundTruth": {
        "header", "sim_time_s", "robot", "robot_velocity", "n", "targets_xy", "target_names",
        "target_ids", "obstacles",
    },
    "MetricsSnapshot": {
        "header", "stamp_ns", "window_s", "fps", "frames", "detections", "detections_per_frame",
        "dropped_frames", "latency_ms", "counters", "class_counts",
    },
}  # fmt: skip


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: type(m).__name__)
def test_wire_names_are_unchanged(msg: Message) -> None:
    env = msgpack.unpackb(msg.encode())
    assert set(env) == {"v", "t", "d"} and env["t"] == msg.TAG and env["v"] == msg.VERSION == 1
    assert set(env["d"]) == WIRE_KEYS[msg.TAG]
    assert set(env["d"]["header"]) == HEADER_KEYS


def test_a_twist_as_written_before_the_field_walk_decodes() -> None:
    # Byte for byte what the hand-written codec of schema version 1 put on the bus.
    payload = msgpack.packb(
        {
            "v": 1,
            "t": "Twist",
            "d": {
                "header": {"stamp_ns": 5, "frame_id": "base_link", "seq": 2, "source": "c"},
                "linear": [0.3, 0, 0.0],
                "angular": [0.0, 0.0, -0.5],
                "input_stamp_ns": 4,
            },
        }
    )
    twist = Twist.decode(payload)
    assert (twist.linear, twist.angular, twist.input_stamp_ns) == ((0.3, 0, 0), (0, 0, -0.5), 4)
    assert (twist.header.mono_ns, twist.header.boot_id) == (0, "")


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: type(m).__name__)
def test_a_newer_version_is_refused(msg: Message) -> None:
    payload = _rewrite(msg.encode(), v=msg.VERSION + 1)
    with pytest.raises(DecodeError, match=f"{msg.TAG}: schema version 2 is newer"):
        type(msg).decode(payload)


WRONG_VALUES: list[object] = [
    None, True, -1, 2**64 - 1, -(2**63), 1.5, float("nan"), float("inf"), "x", b"\x00" * 3,
    b"\x00" * 4096, [], [1, "a"], [float("nan")] * 3, {}, {"a": None}, {1: 2},
]  # fmt: skip


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: type(m).__name__)
def test_any_wrong_value_anywhere_raises_only_decode_error(msg: Message) -> None:
    good = msg.encode()
    body = msgpack.unpackb(good)["d"]
    paths = [(k,) for k in body] + [("header", k) for k in body["header"]]
    for path in paths:
        for value in WRONG_VALUES:
            env = msgpack.unpackb(good, strict_map_key=False)
            target = env["d"]
            for key in path[:-1]:
                target = target[key]
            target[path[-1]] = value
            with contextlib.suppress(DecodeError):  # anything else fails the test
                type(msg).decode(msgpack.packb(env))


def test_truncated_absurd_and_non_finite_arrays() -> None:
    good = MESSAGES[3].encode()  # 3 detections
    body = msgpack.unpackb(good)["d"]
    nan_boxes = np.frombuffer(body["xyxy"], "<f4").copy()
    nan_boxes[5] = np.nan
    for change, match in (
        ({"xyxy": body["xyxy"][:-16]}, "do not fit shape"),
        ({"class_ids": body["class_ids"] + b"\x00" * 4}, "do not fit shape"),
        ({"n": 10**9}, "outside"),
        ({"n": -1}, "outside"),
        ({"xyxy": nan_boxes.tobytes()}, "finite"),
        ({"scores": np.full(3, np.inf, "<f4").tobytes()}, "finite"),
        ({"track_ids": b"\x00" * 8}, "track_ids"),
    ):
        with pytest.raises(DecodeError, match=match):
            Detections.decode(_rewrite(good, **change))
    scan = MESSAGES[6].encode()
    for change in ({"n": 0}, {"n": MAX_SCAN_RAYS + 1}, {"ranges": b""}, {"n": 4}):
        with pytest.raises(DecodeError):
            LaserScan.decode(_rewrite(scan, **change))
    with pytest.raises(DecodeError, match="targets_xy"):
        GroundTruth.decode(_rewrite(MESSAGES[10].encode(), targets_xy=b"\x00" * 16))


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: type(m).__name__)
def test_wire_extras_never_shadow_a_field(msg: Message) -> None:
    names = {f.name for f in dataclasses.fields(msg)}  # type: ignore[arg-type]
    assert not names & set(msg._wire_extras())
