"""What the property-based (hypothesis) fuzz tests share: payload strategies, a valid sample of
every message type to mutate, and a loop that feeds a service's handler payloads and checks its
``bad_input`` count.

Payloads: random bytes; valid msgpack of the wrong shape; the right envelope around a random
body; valid messages with a value swapped for a wrong type, a huge int, a NaN or inf float, huge
bytes, or a key deleted; and valid payloads truncated, bit-flipped or with a length field
overwritten by a huge one. Runs are bounded (``FUZZ``: a fixed number of examples, a deadline
each) and derandomized, so that the suite is repeatable; ``STACK_FUZZ_RANDOM=1`` explores new
examples and ``STACK_FUZZ_SCALE=10`` ten times as many.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import replace
from datetime import timedelta
from typing import Any

import cv2
import msgpack
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from common.boxes import Boxes
from common.clock import wall_ns
from common.codec import Message
from common.errors import DecodeError
from common.messages import (
    CameraAnnouncement,
    ControllerStatus,
    DepthFrame,
    Detections,
    EStop,
    Frame,
    GroundTruth,
    Header,
    LaserScan,
    MetricsSnapshot,
    ServiceCounters,
    Twist,
    WorkerAnnouncement,
)
from common.node import Tally
from rosmsg.convert import LASER_SCAN, TWIST, TWIST_STAMPED, scan_from_ros, twist_from_ros
from rosmsg.images import (
    COMPRESSED_IMAGE,
    IMAGE,
    frame_from_compressed_image,
    frame_from_image,
)

SCALE = max(1, int(os.environ.get("STACK_FUZZ_SCALE", "1")))


def fuzz(examples: int) -> settings:
    """Bounded hypothesis settings: ``examples`` (times STACK_FUZZ_SCALE), 2 s at most each."""
    return settings(
        max_examples=examples * SCALE,
        deadline=timedelta(seconds=2),
        derandomize=not os.environ.get("STACK_FUZZ_RANDOM"),
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )


# ---------------------------------------------------------------------------- valid samples


def header(stamp_ns: int | None = None) -> Header:
    at = wall_ns() if stamp_ns is None else stamp_ns
    return Header(stamp_ns=at, frame_id="camera", seq=7, source="fuzz", mono_ns=5, boot_id="b")


def jpeg(width: int = 16, height: int = 8) -> bytes:
    ramp = np.tile(np.arange(width, dtype=np.uint8) * 8, (height, 1))
    ok, buf = cv2.imencode(".jpg", np.dstack([ramp, ramp[::-1], ramp]))
    assert ok
    return bytes(buf.tobytes())


def samples(stamp_ns: int | None = 1_700_000_000_000_000_000) -> dict[type[Message], list[Message]]:
    """Valid instances of every message type, the seeds of the mutations (stamped now when
    ``stamp_ns`` is None, so that a service takes them as fresh)."""
    h = header(stamp_ns)
    n = 2
    xyxy = np.array([[1, 2, 30, 40], [5, 6, 7, 8]], np.float32)
    dets = Detections(
        header=h,
        image_width=64,
        image_height=48,
        boxes=Boxes(
            xyxy=xyxy,
            scores=np.array([0.9, 0.4], np.float32),
            class_ids=np.arange(n, dtype=np.int32),
            track_ids=np.array([3, -1], np.int32),
        ),
        class_names=("person", "cup"),
        timing_ms={"inference": 1.5},
        model="m",
        backend="onnx/cpu/fp32",
        received_ns=1,
        published_ns=2,
    )
    return {
        Frame: [
            Frame(header=h, encoding="bgr8", width=4, height=2, data=bytes(range(24))),
            Frame(header=h, encoding="mono8", width=3, height=1, data=b"\x00\x01\x02"),
            Frame(header=h, encoding="jpeg", width=16, height=8, data=jpeg()),
        ],
        # With named columns too, so that mutations reach their map, dtypes and bytes.
        Detections: [
            dets,
            replace(
                dets,
                boxes=dets.boxes.with_columns(
                    {
                        "distance_m": np.array([2.5, np.nan]),
                        "mask_id": np.array([1, -1], np.int32),
                        "occluded": np.array([False, True]),
                    }
                ),
            ),
        ],
        Twist: [Twist(header=h, linear=(0.3, 0.0, 0.0), angular=(0.0, 0.0, -0.5))],
        LaserScan: [
            LaserScan(
                header=h,
                angle_min=-1.0,
                angle_increment=0.5,
                range_min=0.1,
                range_max=10.0,
                ranges=np.array([1.0, np.inf, np.nan, 2.0], np.float32),
            )
        ],
        CameraAnnouncement: [
            CameraAnnouncement(camera="front", rate_hz=10.0),
            CameraAnnouncement(
                camera="left",
                width=640,
                height=480,
                rate_hz=5.0,
                mount_yaw_deg=90.0,
                hfov_deg=70.0,
                frame_id="camera_left",
                source="sim",
                depth=True,
                mount_height_m=0.6,
                mount_x_m=0.1,
            ),
        ],
        DepthFrame: [
            DepthFrame(
                header=h,
                encoding="16UC1",
                width=3,
                height=2,
                data=np.array([0, 500, 1000, 1500, 2000, 65535], "<u2").tobytes(),
                fx=2.0,
                fy=2.0,
                cx=1.5,
                cy=1.0,
                range_min_m=0.2,
                range_max_m=10.0,
            ),
            DepthFrame(
                header=h,
                encoding="32FC1",
                width=2,
                height=1,
                data=np.array([1.25, np.nan], "<f4").tobytes(),
                fx=1.0,
                fy=1.0,
                cx=1.0,
                cy=0.5,
            ),
        ],
        WorkerAnnouncement: [
            WorkerAnnouncement(
                worker="gpu",
                capacity_hz=120.0,
                input_size=640,
                backend="cuda",
                max_batch=4,
                prefixes=("robot1", "site/robot2"),
                seq=2,
            )
        ],
        ControllerStatus: [
            ControllerStatus(header=h, mode="follow", target="person", state="following")
        ],
        GroundTruth: [
            GroundTruth(
                header=h,
                sim_time_s=1.0,
                robot=(0.0, 1.0, 0.5),
                targets_xy=np.ones((1, 2)),
                target_names=("person",),
                target_ids=("p1",),
            )
        ],
        EStop: [EStop(header=h, engaged=True, reason="test")],
        ServiceCounters: [ServiceCounters(header=h, service="detector", counters={"a": 1})],
        MetricsSnapshot: [
            MetricsSnapshot(
                header=h,
                window_s=10.0,
                fps=5.0,
                frames=50,
                detections=3,
                detections_per_frame=0.06,
                dropped_frames=1,
                latency_ms={"end_to_end": {"p50": 80.0}},
                counters={"detector.bad_input": 2},
                class_counts={"person": 3},
            )
        ],
    }


def to_stack(msg: Any) -> Any:
    """A ROS message decoded from the bus as the stack takes it in (the bridge, the robot)."""
    kind = msg.__msgtype__
    if kind == IMAGE:
        return frame_from_image(msg, source="ros2")
    if kind == COMPRESSED_IMAGE:
        return frame_from_compressed_image(msg, source="ros2")
    if kind == LASER_SCAN:
        return scan_from_ros(msg, source="ros2")
    if kind in (TWIST, TWIST_STAMPED):
        return twist_from_ros(msg, source="ros2", received_ns=1)
    return msg  # Detection2DArray: read back by the bridge's benchmark, as it is


# ---------------------------------------------------------------------------- strategies

# Values that break decoders: wrong types, the edges of msgpack's ints, NaN and inf.
NASTY_INTS = [0, -1, 1, 2**31 - 1, -(2**31), 2**32, 2**63 - 1, -(2**63), 2**64 - 1]
SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.sampled_from(NASTY_INTS),
    st.integers(min_value=-(2**63), max_value=2**64 - 1),
    st.floats(),  # NaN, inf and -inf included
    st.text(max_size=16),
    st.binary(max_size=64),
    st.sampled_from([b"\x00" * 100_000, "x" * 100_000]),
)
# One level of nesting: st.recursive costs hypothesis twice the time per example, and a
# decoder refuses a wrong container before it looks inside.
VALUES = st.one_of(
    SCALARS,
    SCALARS,
    st.lists(SCALARS, max_size=3),
    st.dictionaries(st.text(max_size=4) | st.integers(-5, 5), SCALARS, max_size=3),
)


def packed(value: Any) -> bytes:
    out = msgpack.packb(value, use_bin_type=True)
    assert isinstance(out, bytes)
    return out


def _paths(obj: Any, here: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    """Every place in a decoded envelope where a value can be swapped or deleted."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield (*here, k)
            yield from _paths(v, (*here, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield (*here, i)
            yield from _paths(v, (*here, i))


@st.composite
def value_mutation(draw: st.DrawFn, valid: bytes) -> bytes:
    """``valid`` (a msgpack payload) with one value swapped for another, or a key deleted."""
    obj = msgpack.unpackb(valid, raw=False)
    for _ in range(draw(st.integers(1, 2))):
        path = draw(st.sampled_from(list(_paths(obj))))
        parent = obj
        for step in path[:-1]:
            parent = parent[step]
        if isinstance(parent, dict) and draw(st.booleans()) and draw(st.booleans()):
            del parent[path[-1]]
        else:
            parent[path[-1]] = draw(VALUES)
        if not isinstance(obj, dict) or not list(_paths(obj)):
            break
    return packed(obj)


@st.composite
def byte_mutation(draw: st.DrawFn, valid: bytes) -> bytes:
    """``valid`` truncated, bit-flipped, with bytes inserted, or a 4- or 8-byte field (a
    length, a count) overwritten with a huge or negative number."""
    data = bytearray(valid)
    for _ in range(draw(st.integers(1, 2))):
        if not data:
            break
        kind = draw(st.sampled_from(["truncate", "flip", "insert", "huge", "huge", "huge"]))
        i = draw(st.integers(0, len(data) - 1))
        if kind == "truncate":
            del data[i:]
        elif kind == "flip":
            data[i] ^= 1 << draw(st.integers(0, 7))
        elif kind == "insert":
            data[i:i] = draw(st.binary(min_size=1, max_size=8))
        else:
            size = draw(st.sampled_from([4, 8]))
            fill = draw(st.sampled_from([b"\xff", b"\x7f", b"\x80"])) + b"\xff" * (size - 1)
            order = draw(st.sampled_from([1, -1]))  # big- or little-endian
            data[i : i + size] = fill[::order]
    return bytes(data)


def payloads(
    tag: str, valid: list[bytes], *, msgpack_shapes: bool = True
) -> st.SearchStrategy[bytes]:
    """Every kind of payload for a decoder whose valid payloads look like ``valid``."""
    kinds = [
        st.binary(max_size=256),
        st.sampled_from(valid).flatmap(byte_mutation),
    ]
    if msgpack_shapes:
        kinds += [
            VALUES.map(packed),
            st.fixed_dictionaries(
                {"v": st.sampled_from([1, 1, 0, 2, -1]), "t": st.just(tag), "d": VALUES}
            ).map(packed),
            st.sampled_from(valid).flatmap(value_mutation),
            st.sampled_from(valid).flatmap(value_mutation),
        ]
    return st.one_of(kinds)


def message_payloads(cls: type[Message], *, fresh: bool = False) -> st.SearchStrategy[bytes]:
    """Payloads for ``cls.decode``; ``fresh``: mutations of messages stamped now."""
    valid = samples(None if fresh else 1_700_000_000_000_000_000)[cls]
    return payloads(cls.TAG, [m.encode() for m in valid])


#: A header's stamp and seq at the edges of what consumers can carry: a ROS Time's int32
#: seconds (2038), a Foxglove timestamp's uint32 seconds (2106), MCAP's uint32 sequence.
EDGE_STAMPS_NS = [0, (2**31 - 1) * 10**9, 2**31 * 10**9, 2**32 * 10**9, 2**63, 2**64 - 1]
EDGE_SEQS = [0, 2**32 - 1, 2**32, 2**64 - 1]


def edge_stamped(cls: type[Message]) -> list[bytes]:
    """Valid ``cls`` payloads, one for each edge stamp (with the edge seqs in turn): few
    enough to feed every one, where a strategy would seldom draw them."""
    msg: Any = samples()[cls][0]
    return [
        replace(msg, header=replace(msg.header, stamp_ns=at, seq=seq)).encode()
        for at, seq in zip(EDGE_STAMPS_NS, [*EDGE_SEQS, *EDGE_SEQS], strict=False)
    ]


# ---------------------------------------------------------------------------- feeding a handler

HANDLER_EXAMPLES = 50  # per handler: about 750 payloads in all, in a few seconds


def rejected_by(decode: Callable[[bytes], Any], payload: bytes) -> bool:
    try:
        decode(payload)
    except DecodeError:
        return True
    return False


def fuzz_handler(
    tally: Tally,
    feed: Callable[[bytes], None],
    key: str,
    decode: Callable[[bytes], Any],
    strategy: st.SearchStrategy[bytes],
    examples: int = HANDLER_EXAMPLES,
) -> int:
    """Feed a handler (``feed``: it, called with one payload) generated payloads: ``bad_input``
    grows by one exactly for each that ``decode`` rejects; an exception escaping the handler
    fails the test. ``key`` names the handler's key in failures. Returns how many it was fed."""
    counts = {"rejected": 0, "taken": 0}

    @fuzz(examples)
    @given(payload=strategy)
    def check(payload: bytes) -> None:
        before = tally.counters.get("bad_input")
        feed(payload)
        rejected = rejected_by(decode, payload)
        assert tally.counters.get("bad_input") - before == int(rejected), key
        counts["rejected" if rejected else "taken"] += 1

    check()
    assert counts["rejected"] > 0, f"{key}: no payload was rejected: {counts}"
    return counts["rejected"] + counts["taken"]


def message_handler(
    tally: Tally,
    feed: Callable[[bytes], None],
    key: str,
    cls: type[Message],
    examples: int = HANDLER_EXAMPLES,
) -> int:
    """Fuzz the handler of ``cls`` messages on ``key`` with ``cls``'s payloads."""
    return fuzz_handler(tally, feed, key, cls.decode, message_payloads(cls, fresh=True), examples)
