"""Property-based fuzzing of every decoder of bytes from the bus (issue 13, item 7): each
generated payload is either decoded to a valid message or rejected with the one typed error.

Any other exception fails the test. What is accepted must be a message that encodes again and
decodes to the same bytes, and a Frame's pixels must decode to an image or an ImageError.
"""

from __future__ import annotations

import inspect

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import common.messages
from common.codec import Message
from common.errors import DecodeError, ImageError
from common.frames import frame_to_bgr, jpeg_size
from common.messages import Frame
from tests.unit.fuzz import byte_mutation, fuzz, header, jpeg, message_payloads, samples

MESSAGE_TYPES = sorted(
    (
        cls
        for _, cls in inspect.getmembers(common.messages, inspect.isclass)
        if issubclass(cls, Message) and cls is not Message
    ),
    key=lambda cls: cls.TAG,
)


def decoded_or_rejected(cls: type[Message], payload: bytes) -> Message | None:
    try:
        msg = cls.decode(payload)
    except DecodeError:
        return None
    assert type(msg) is cls
    again = msg.encode()
    assert cls.decode(again).encode() == again  # accepted means valid: it round-trips
    return msg


def test_every_message_type_has_valid_samples_to_mutate() -> None:
    assert set(samples()) == set(MESSAGE_TYPES)


@pytest.mark.parametrize("cls", MESSAGE_TYPES, ids=lambda cls: cls.TAG)
def test_every_decoder_decodes_or_raises_decode_error(cls: type[Message]) -> None:
    @fuzz(120)
    @given(payload=message_payloads(cls))
    def check(payload: bytes) -> None:
        msg = decoded_or_rejected(cls, payload)
        if isinstance(msg, Frame):
            _pixels_or_image_error(msg)

    check()


def _pixels_or_image_error(frame: Frame) -> None:
    try:
        image = frame_to_bgr(frame)
    except ImageError:
        return
    assert image.shape == (frame.height, frame.width, 3) and image.dtype == np.uint8


def test_jpeg_frames_decode_to_pixels_or_an_image_error() -> None:
    """The pixels of a Frame that decoded: a mutated JPEG (a lying size, a cut body, a flipped
    marker) gives the image its header promised, or ImageError."""
    good = jpeg(16, 8)

    @fuzz(150)
    @given(
        data=st.one_of(byte_mutation(good), st.binary(max_size=64).map(lambda b: b"\xff\xd8" + b)),
        size=st.sampled_from([(16, 8), (8, 16), (1, 1), (16384, 16384)]),
    )
    def check(data: bytes, size: tuple[int, int]) -> None:
        found = jpeg_size(data)
        assert found is None or (isinstance(found, tuple) and len(found) == 2)
        try:
            frame = Frame(
                header=header(), encoding="jpeg", width=size[0], height=size[1], data=data
            )
        except ValueError:
            assert not data  # only an empty jpeg is refused by the message itself
            return
        _pixels_or_image_error(frame)

    check()
