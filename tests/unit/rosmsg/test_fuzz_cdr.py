"""Property-based fuzzing of the ROS 2 side's decoders (issue 13, item 7): CDR payloads and
rmw_zenoh attachments, valid ones mutated (truncated, bit-flipped, a length made huge) and
random bytes, go through the bridge's and the simulated robot's whole inbound path: the result
is the stack's message, or DecodeError and nothing else."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from common.errors import DecodeError
from common.messages import Detections, Frame, LaserScan, Twist
from rosmsg.convert import (
    DETECTION_2D_ARRAY,
    LASER_SCAN,
    TWIST,
    TWIST_STAMPED,
    cdr_decode,
    cdr_encode,
    detections_to_ros,
    scan_to_ros,
    twist_to_ros,
)
from rosmsg.distro import RosDistro
from rosmsg.images import (
    COMPRESSED_IMAGE,
    IMAGE,
    frame_to_compressed_image,
    frame_to_image,
)
from rosmsg.wire import ATTACHMENT_SIZE, Attachment, gid_for
from tests.unit.fuzz import byte_mutation, fuzz, payloads, samples, to_stack

DISTRO = RosDistro.JAZZY
S = samples()


# Each ROS type the stack decodes, with valid messages of it to mutate.
VALID: dict[str, Callable[[], list[Any]]] = {
    IMAGE: lambda: [frame_to_image(DISTRO, f) for f in S[Frame] if f.encoding != "jpeg"],
    COMPRESSED_IMAGE: lambda: [
        frame_to_compressed_image(DISTRO, f) for f in S[Frame] if f.encoding == "jpeg"
    ],
    LASER_SCAN: lambda: [scan_to_ros(DISTRO, s) for s in S[LaserScan]],
    TWIST: lambda: [twist_to_ros(DISTRO, t) for t in S[Twist]],
    TWIST_STAMPED: lambda: [twist_to_ros(DISTRO, t, stamped=True) for t in S[Twist]],
    DETECTION_2D_ARRAY: lambda: [detections_to_ros(DISTRO, d) for d in S[Detections]],
}


@pytest.mark.parametrize("ros_type", sorted(VALID))
def test_every_inbound_ros_payload_is_translated_or_a_decode_error(ros_type: str) -> None:
    valid = [cdr_encode(DISTRO, ros_type, m) for m in VALID[ros_type]()]
    assert all(to_stack(cdr_decode(DISTRO, ros_type, v)) is not None for v in valid)

    @fuzz(100)
    @given(payload=payloads(ros_type, valid, msgpack_shapes=False))
    def check(payload: bytes) -> None:
        try:
            result = to_stack(cdr_decode(DISTRO, ros_type, memoryview(payload)))
        except DecodeError:
            return
        if isinstance(result, Frame | LaserScan | Twist):
            type(result).decode(result.encode())  # what is taken in is a valid message

    check()


def test_attachments_decode_or_raise_decode_error() -> None:
    valid = Attachment(5, 1_700_000_000_000_000_000, gid_for("fuzz")).encode()

    @fuzz(100)
    @given(
        data=st.one_of(
            st.binary(max_size=2 * ATTACHMENT_SIZE),
            st.binary(min_size=ATTACHMENT_SIZE, max_size=ATTACHMENT_SIZE),
            byte_mutation(valid),
        )
    )
    def check(data: bytes) -> None:
        try:
            found = Attachment.decode(data)
        except DecodeError:
            return
        assert Attachment.decode(found.encode()) == found

    check()
